"""Pure closed-loop dynamics: ``step_env(state, u, params, r) -> state``.

The API layer (environments, reproduction) calls :func:`step_env` once per
control period; the input ``u`` and the reference command ``r`` are held
(zero-order hold) for ``params.substeps`` Euler steps of ``params.dt``, and the
observer nodes receive the held local inputs ``u_i`` (the columns of ``u`` they
know, through ``Bbar_i``). See :mod:`dobs_envs.sim.numpy_step` for the scheme.
"""
from __future__ import annotations

import numpy as np

from ..linalg.validation import as_array
from .period_kernel import HAVE_NUMBA, control_period_compiled
from .numpy_step import control_period_numpy
from .state import SimParams, SimState

__all__ = ["step_env", "estimates", "outputs", "estimation_errors", "BACKENDS"]

BACKENDS = ("numba", "numpy")


def _check_input(name, a, batch, width):
    """Finite real ``(batch, width)`` float64 copy of ``a`` (a 1-D ``a`` is one batch row)."""
    a = as_array(a, name)
    if a.ndim == 1:
        a = a[None]
    if a.shape != (batch, width):
        raise ValueError(f"{name} must have shape ({batch}, {width}) (batch, inputs), got {np.shape(a)}")
    return a


def step_env(state: SimState, u, params: SimParams, r=None, *, backend: str = "numba", validate: bool = True) -> SimState:
    """Advance one control period (``params.substeps`` Euler steps).

    Parameters
    ----------
    state : SimState with batch size B.
    u : (B, m) held control input (stacked channels ``u = col(u^k)``).
    params : SimParams.
    r : (B, m) held reference command of eq. (refxdy), or None (zeros).
    backend : "numba" (compiled, default) or "numpy" (reference implementation).
    validate : check shapes / finiteness of ``u`` and ``r`` (the environments
        validate actions themselves and pass False).

    Returns
    -------
    SimState : the new state (the input state is not modified).
    """
    Bsz = state.x.shape[0]
    m = params.B.shape[1]
    if validate:
        u = _check_input("u", u, Bsz, m)
        r = np.zeros((Bsz, m)) if r is None else _check_input("r", r, Bsz, m)
    elif r is None:
        r = np.zeros((Bsz, m))
    if backend == "numba" and HAVE_NUMBA:
        fn = control_period_compiled
    elif backend in BACKENDS:
        fn = control_period_numpy
    else:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    x, z, g, gs, v, xr = fn(state.x, state.z, state.gamma, state.gamma_s, state.v, state.x_r, u, r, params)
    return SimState(t=state.t + params.dt * params.substeps, x=x, z=z, gamma=g, gamma_s=gs, v=v, x_r=xr)


def outputs(state: SimState, params: SimParams) -> np.ndarray:
    """Local measured outputs ``y_i = C_i x`` (eq. localmeasure), shape (B, N, p) (zero-padded)."""
    return np.einsum("ipn,bn->bip", params.C, state.x)


def estimates(state: SimState, params: SimParams) -> np.ndarray:
    """State estimates ``xhat_i = z_i + Gbar_i y_i`` (eq. hatxieq), shape (B, N, n)."""
    return state.z + np.einsum("inp,bip->bin", params.G_bar, outputs(state, params))


def estimation_errors(state: SimState, params: SimParams) -> np.ndarray:
    """``||xhat_i - x||`` per node, shape (B, N)."""
    return np.linalg.norm(estimates(state, params) - state.x[:, None, :], axis=-1)
