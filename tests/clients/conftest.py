"""The clients suite: the MARL libraries people train with, driven for real (no mocks).

They come with the ``clients`` extra (``pip install ".[rl,test,clients]"``). Without it the
tests are skipped with that hint, except in CI (``CI`` set), where a missing client fails.
"""
from __future__ import annotations

import importlib
import os

import pytest


def require(module: str):
    """``import module``; skip when it is missing, fail in CI (``.ci/run`` installs the clients)."""
    if os.environ.get("CI"):
        return importlib.import_module(module)
    return pytest.importorskip(module, reason=f"{module} comes with the clients extra: pip install '.[clients]'")
