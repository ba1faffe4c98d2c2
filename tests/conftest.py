"""Set-up shared by every test module and every pytest-xdist worker (``-n``: ``addopts`` in pyproject.toml).

XLA on one thread per test process, as the training commands run it (:func:`agents.training.xla.xla_threads`:
``PJRT_NPROC=1`` unless set, the flags of :mod:`agents.training.xla`), before any test computes with JAX: the
workers share the machine's cores, and which test module starts JAX first in a worker depends on the
distribution. Tests of the thread set-up itself run fresh processes with their own environment.

The directory this process imports the project from (the checkout, with ``python -m pytest`` from its root)
goes first on ``PYTHONPATH``, so that every subprocess a test starts, and every Ray worker, runs the same
code as the test, whatever its working directory (rl-zoo3's CLI runs in a scratch directory, Ray's workers in
Ray's own). It also keeps numba's compiled kernels in one place: numba caches them beside the source file it
compiled, so a subprocess that imported the installed copy instead compiled the whole engine again, cold
(2-3 minutes each on the 2-core machine; the heavy clients' suite, in its own virtual environment, runs the
same checkout and finds the kernels the main suite compiled). An installed copy (``site-packages``) is left
where it is: ahead of the standard library on ``PYTHONPATH`` it could shadow it.
"""
import os
import site
import sysconfig

import dobs_envs
from agents.training.xla import xla_threads


def _tested_tree_first() -> None:
    root = os.path.dirname(os.path.dirname(os.path.abspath(dobs_envs.__file__)))
    installed = {os.path.abspath(p) for p in [*site.getsitepackages(), site.getusersitepackages(),
                                              sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]}
    if root in installed:
        return
    parts = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    if root not in parts:
        os.environ["PYTHONPATH"] = os.pathsep.join([root, *parts])


_tested_tree_first()
xla_threads(1)
