"""``dobs-envs`` command line: one sub-command per job.

Sub-commands live next to the code they drive and register themselves through an
``add_parser(subparsers)`` function:

- ``reproduce``  -> :mod:`dobs_envs.reproduce` (the paper's numerical examples)
- ``train``, ``evaluate``, ``benchmark``, ``tune`` -> :mod:`agents.cli` (needs the ``rl`` extra)
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys

#: module -> the sub-commands it registers (used for a helpful stub when its import fails)
_SUBCOMMAND_MODULES = {
    "dobs_envs.reproduce": ("reproduce",),
    "agents.cli": ("train", "evaluate", "benchmark", "tune"),
}


class OneLineParser(argparse.ArgumentParser):
    """Usage errors are one line on stderr (``prog: error: message``, the usage on ``-h``), exit status 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} -h)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="dobs-envs",
        description="Distributed-observer control benchmark (Cao & Yin).",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    for name, commands in _SUBCOMMAND_MODULES.items():
        try:
            module = importlib.import_module(name)
        except ImportError as exc:  # e.g. the rl extra (torch, stable-baselines3) is not installed
            missing = getattr(exc, "name", None) or str(exc)
            for command in commands:
                stub = sub.add_parser(command, help=f"unavailable: missing {missing}")
                stub.set_defaults(func=lambda args, _m=missing: sys.exit(
                    f"dobs-envs: this command needs {_m}; install it with: pip install 'dobs-envs[rl]'"))
            continue
        module.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        result = args.func(args)
        sys.stdout.flush()  # a closed pipe is found here, inside the handler, not at interpreter exit
    except KeyboardInterrupt:  # Ctrl-C: one line and 128 + SIGINT, no traceback (train/benchmark say more)
        print("dobs-envs: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # stdout closed early (`dobs-envs ... | head`): no traceback; Python's documented recipe
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nothing more is flushed to the pipe
        return 1
    return int(result or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
