"""The compilation settings of the simulation kernels (:mod:`.period_kernel`, :mod:`.fault_kernel`), in one place.

``FASTMATH``: LLVM fast-math flags of the kernels, FMA contraction (``contract``) only. Not ``reassoc``
(a copy's sums must not be reordered differently in the scalar and the tiled layout), not ``nsz``
(``0.0 + a*b`` must stay an FMA with 0, never a bare product that a following addition could contract
either way), not ``nnan``/``ninf`` (NaN and inf propagate as IEEE arithmetic says: an overflowing
observer yields a non-finite state the environment detects and terminates on, instead of undefined
behaviour). ``njit`` / ``njit_inline``: cached, GIL-free, numpy error model (``njit_inline``: inlined
into its callers at the IR level, where ``if arg is None:`` branches are pruned per specialisation when
the argument is None; ``len(tuple_arg)`` is made a constant only in a compiled function's own body, not in
an inlined one). ``njit_inline`` is for small helpers: numba copies an inlined body once per call site, at a
cost that grows with the body's size times its number of variables, so a large body is a compiled function
of its own (``period_kernel.period_tile``).
"""
from __future__ import annotations

FASTMATH = {"contract"}

try:  # numba is a hard dependency, but keep the package importable without it
    import numba

    njit = numba.njit(cache=True, fastmath=FASTMATH, nogil=True, error_model="numpy")
    njit_inline = numba.njit(cache=True, fastmath=FASTMATH, nogil=True, error_model="numpy", inline="always")
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    HAVE_NUMBA = False

    def njit(f):
        return f

    njit_inline = njit

__all__ = ["FASTMATH", "HAVE_NUMBA", "njit", "njit_inline"]
