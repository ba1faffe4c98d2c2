"""The documentation's RLlib, BenchMARL and rejax blocks (marked ``<!-- snippet: heavy-clients ... -->`` in
docs/*.md) run here, in the heavy-clients virtual environment; the main suite's
tests/test_docs_snippets.py runs every other block and skips these."""
from __future__ import annotations

import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from test_docs_snippets import SNIPPETS, run_snippet  # noqa: E402

HEAVY = [s for s in SNIPPETS if s[2] and "snippet: heavy-clients" in s[2]]


def test_the_heavy_blocks_are_found():
    assert len(HEAVY) == 3, [s[0] for s in HEAVY]


@pytest.mark.parametrize("sid,code,marker", HEAVY, ids=[s[0] for s in HEAVY])
def test_heavy_block_runs(sid, code, marker, tmp_path, monkeypatch):
    import ray

    try:
        run_snippet(sid, code, tmp_path, monkeypatch)
    finally:
        ray.shutdown()  # the RLlib block starts a local Ray: its workers would slow the next block down
