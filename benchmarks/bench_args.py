"""Command-line pieces shared by the benchmark scripts: the JSON record's ``--out`` / ``--overwrite`` and the checks of
their positive counts (usage errors exit 2 with one line, an existing record is kept unless ``--overwrite``)."""
from __future__ import annotations

import argparse
import json
import os


def add_record_args(ap: argparse.ArgumentParser) -> None:
    """``--out`` (the JSON record, written only when given) and ``--overwrite``."""
    ap.add_argument("--out", default=None, help="write the JSON record here")
    ap.add_argument("--overwrite", action="store_true", help="replace an existing --out file")


def check_args(ap: argparse.ArgumentParser, args: argparse.Namespace, positive: tuple = ()) -> None:
    """``ap.error`` unless every option named in ``positive`` is at least 1 and ``--out`` is new (or ``--overwrite``)."""
    for name in positive:
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be a positive integer, got {getattr(args, name)}")
    if args.out and os.path.exists(args.out) and not args.overwrite:
        ap.error(f"--out {args.out} exists; pass --overwrite to replace it")


def jax_runtime() -> dict:
    """The JAX version and the XLA settings a record was measured with, and the load average at its end."""
    import jax

    return {"jax": jax.__version__, "PJRT_NPROC": os.environ.get("PJRT_NPROC"), "XLA_FLAGS": os.environ.get("XLA_FLAGS"),
            "load_avg": [round(x, 2) for x in os.getloadavg()]}


def write_record(args: argparse.Namespace, record: dict) -> None:
    """Write ``record`` as JSON to ``--out`` if given (replacing a file only with ``--overwrite``)."""
    if args.out:
        with open(args.out, "w" if args.overwrite else "x") as f:
            json.dump(record, f, indent=1)
        print(f"wrote {args.out}")
