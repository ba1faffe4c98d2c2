"""Set-up shared by every test module and every pytest-xdist worker (``-n``: ``addopts`` in pyproject.toml).

XLA on one thread per test process, as the training commands run it (:func:`agents.training.xla.xla_threads`:
``PJRT_NPROC=1`` unless set, the flags of :mod:`agents.training.xla`), before any test computes with JAX: the
workers share the machine's cores, and which test module starts JAX first in a worker depends on the
distribution. Tests of the thread set-up itself run fresh processes with their own environment.
"""
from agents.training.xla import xla_threads

xla_threads(1)
