"""State and parameters of the closed-loop simulation (gymnax style: small frozen
dataclasses, batch dimension first).

The simulated system is

- the plant, eq. (LTIsys): ``x' = A x + B u + B_v v``,
- the unknown-input exosystem (NE3): ``v' = S v`` (propagated exactly),
- the reference model, eq. (refxdy): ``x_r' = (A + B K) x_r + B r``,
- the ``N`` observer nodes, eqs. (obidynamic), (barEFGB), (H_idefine):
  ``z_i' = Ebar_i z_i + Fbar_i y_i + Bbar_i u - H_i``, ``xhat_i = z_i + Gbar_i y_i``,
- the adaptive gains, eq. (gammaiis) and its leakage variant (gagasbeta):
  ``gamma_i' = -sigma_i gamma_i + phi_i ||eps_iu||^2``,
  ``gamma_is' = -sigma_is gamma_is + phi_is ||eps_iu||``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
import numpy as np
from scipy.linalg import expm

from ..linalg.validation import as_array
from .kernel_args import ROW_MATRICES, KernelArgs, StateArrays, compress_rows, kernel_args_of, pack_kernel_args

__all__ = ["SimState", "SimParams", "KernelArgs", "StateArrays", "ROW_MATRICES", "compress_rows", "pack_kernel_args"]


def _ro(a, shape=None) -> np.ndarray:
    out = np.ascontiguousarray(np.array(a, dtype=np.float64, copy=True))
    if shape is not None:
        out = out.reshape(shape)
    out.flags.writeable = False
    return out


def _ro_int(a):
    out = np.ascontiguousarray(np.array(a, dtype=np.int64, copy=True))
    out.flags.writeable = False
    return out


def _ro_bool(a):
    out = np.ascontiguousarray(np.array(a, dtype=np.bool_, copy=True))
    out.flags.writeable = False
    return out


def _thin_projector_bases(P_u: np.ndarray):
    """For each orthogonal projector ``P_u,i = T_iu T_iu^T`` return the thinner
    orthonormal basis: of its range (rank <= n/2) or of its complement Im T_id.
    Padded with zero columns to a common width r = max_i min(rank, n - rank)."""
    N, n, _ = P_u.shape
    bases, is_range = [], []
    for i in range(N):
        w, V = np.linalg.eigh(0.5 * (P_u[i] + P_u[i].T))  # eigenvalues 0 / 1
        rng_ = V[:, w > 0.5]
        cmp_ = V[:, w <= 0.5]
        if rng_.shape[1] <= cmp_.shape[1]:
            bases.append(rng_); is_range.append(True)
        else:
            bases.append(cmp_); is_range.append(False)
    r = max(1, max(b.shape[1] for b in bases))
    Q = np.zeros((N, n, r))
    for i, b in enumerate(bases):
        Q[i, :, : b.shape[1]] = b
    return Q, np.array(is_range)


def _neighbour_lists(adj: np.ndarray):
    """Padded neighbour index / weight lists of a weighted adjacency matrix."""
    N = adj.shape[0]
    nbrs = [np.flatnonzero(adj[i]) for i in range(N)]
    maxdeg = max(1, max(len(x) for x in nbrs))
    idx = np.zeros((N, maxdeg), dtype=np.int64)
    wts = np.zeros((N, maxdeg))
    for i, nb in enumerate(nbrs):
        idx[i, : len(nb)] = nb
        wts[i, : len(nb)] = adj[i, nb]
    return idx, wts


@dataclass(frozen=True)
class SimState:
    """Batched simulation state. All arrays have the batch dimension first.

    Attributes
    ----------
    t : (B,) simulated time.
    x : (B, n) plant state.
    z : (B, N, n) observer node states (eq. zidynamic; ``z_i(0) = 0`` in the paper).
    gamma, gamma_s : (B, N) adaptive consensus gains ``gamma_i``, ``gamma_is``.
    v : (B, m_v) unknown input (exosystem state, or a held external signal).
    x_r : (B, n) reference-model state (zeros when there is no reference).
    """

    t: np.ndarray
    x: np.ndarray
    z: np.ndarray
    gamma: np.ndarray
    gamma_s: np.ndarray
    v: np.ndarray
    x_r: np.ndarray

    @property
    def batch_size(self) -> int:
        return self.x.shape[0]

    def replace(self, **changes) -> "SimState":
        return replace(self, **changes)

    def index(self, idx) -> "SimState":
        """Sub-batch ``idx`` (keeps the batch axis)."""
        idx = np.atleast_1d(np.asarray(idx))
        return SimState(*(getattr(self, f)[idx] for f in ("t", "x", "z", "gamma", "gamma_s", "v", "x_r")))


@dataclass(frozen=True)
class SimParams:
    """Constant arrays and constants of one closed-loop configuration.

    Build it with :meth:`from_design`. All arrays are read-only float64 and
    C-contiguous (the compiled kernel relies on it).
    """

    A: np.ndarray  # (n, n)
    B: np.ndarray  # (n, m)
    B_v: np.ndarray  # (n, m_v)
    C: np.ndarray  # (N, p, n)
    E_bar: np.ndarray  # (N, n, n)
    F_bar: np.ndarray  # (N, n, p)
    G_bar: np.ndarray  # (N, n, p)
    B_bar: np.ndarray  # (N, n, m)
    P_u: np.ndarray  # (N, n, n)
    laplacian: np.ndarray  # (N, N)
    A_r: np.ndarray  # (n, n) reference closed loop A + B K (zeros if no reference)
    phi: np.ndarray  # (N,)
    phi_s: np.ndarray  # (N,)
    sigma: np.ndarray  # (N,)
    sigma_s: np.ndarray  # (N,)
    S_v: np.ndarray  # (m_v, m_v) exosystem matrix (zeros: v held constant)
    Phi_v: np.ndarray  # (m_v, m_v) exact exosystem transition expm(S_v dt) over one Euler step
    # compact forms used by the compiled kernel (same operators as P_u and laplacian):
    Q_proj: np.ndarray = None  # (N, n, r) orthonormal basis of Im T_iu (proj_range) or of Im T_id
    proj_range: np.ndarray = None  # (N,) bool: P_u,i = Q Q^T (True) or I - Q Q^T (False)
    nbr_idx: np.ndarray = None  # (N, max degree) neighbour indices (padding: weight 0)
    nbr_w: np.ndarray = None  # (N, max degree) edge weights a_ij
    degree: np.ndarray = None  # (N,) sum_j a_ij
    dt: float = 1e-3
    substeps: int = 1
    has_reference: bool = False
    has_exosystem: bool = False

    @property
    def n_states(self) -> int:
        return self.A.shape[0]

    @property
    def n_nodes(self) -> int:
        return self.E_bar.shape[0]

    @property
    def n_inputs(self) -> int:
        return self.B.shape[1]

    @property
    def n_unknown(self) -> int:
        return self.B_v.shape[1]

    @property
    def control_period(self) -> float:
        return self.dt * self.substeps

    @cached_property
    def kernel_args(self) -> KernelArgs:
        """The kernel's constants as one :class:`~dobs_envs.sim.kernel_args.KernelArgs`: every field the
        attribute of that name (:func:`~dobs_envs.sim.kernel_args.kernel_args_of`; built on first use, then cached)."""
        return kernel_args_of(self)

    @cached_property
    def kernel_packed(self) -> tuple:
        """:attr:`kernel_args` packed into two buffers ``(KF, KI)`` (:func:`pack_kernel_args`; built once): what
        compiled code is called with from Python."""
        return pack_kernel_args(self.kernel_args)

    @cached_property
    def kernel_tuple(self) -> tuple:
        """:attr:`kernel_args` as a plain tuple (same field order)."""
        return tuple(self.kernel_args)

    @classmethod
    def from_design(
        cls,
        design,
        *,
        phi=0.2,
        phi_s=0.5,
        sigma=0.0,
        sigma_s=0.0,
        dt: float = 1e-3,
        substeps: int = 1,
        exosystem=None,
        K_ref=None,
    ) -> "SimParams":
        """Parameters from an :class:`~dobs_envs.design.observer.ObserverDesign`.

        Parameters
        ----------
        design : ObserverDesign
        phi, phi_s : float or (N,) step sizes of eq. (gammaiis) (``phi_s = 0`` with
            ``gamma_s(0) = 0`` removes the discontinuous term: the NE2 ablation).
        sigma, sigma_s : float or (N,) leakage coefficients of eq. (gagasbeta)
            (0 gives eq. (gammaiis)).
        dt : Euler step (s). substeps : Euler steps per control period (ZOH).
        exosystem : (m_v, m_v) matrix ``S`` of ``v' = S v`` or None (v held
            between control periods, e.g. set by an environment).
        K_ref : (m, n) gain of the reference model (refxdy), or None for no reference.
        """
        N = design.E_bar.shape[0]
        n = design.A.shape[0]
        m = design.B.shape[1]
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive finite float, got {dt!r}")
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be a positive integer, got {substeps!r}")

        def per_node(name, val):
            arr = np.broadcast_to(np.asarray(val, dtype=float), (N,)) if np.ndim(val) == 0 else np.asarray(val, dtype=float)
            if arr.shape != (N,):
                raise ValueError(f"{name} must be a scalar or have shape ({N},), got {np.shape(val)}")
            if not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ValueError(f"{name} must be finite and nonnegative (paper: positive step sizes / leakage), got {arr}")
            return _ro(arr)

        B_v = np.asarray(design.B_v, dtype=float).reshape(n, -1)
        m_v = B_v.shape[1]
        if exosystem is not None:
            S = np.asarray(exosystem, dtype=float)
            if S.shape != (m_v, m_v):
                raise ValueError(f"exosystem must have shape ({m_v}, {m_v}) to match B_v, got {S.shape}")
        else:
            S = np.zeros((m_v, m_v))
        if K_ref is not None:
            K_ref = np.asarray(K_ref, dtype=float)
            if K_ref.shape != (m, n):
                raise ValueError(f"K_ref must have shape ({m}, {n}), got {K_ref.shape}")
            A_r = design.A + design.B @ K_ref
        else:
            A_r = np.zeros((n, n))
        adj = np.asarray(design.adjacency, dtype=float)
        lap = np.diag(adj.sum(axis=1)) - adj
        Q_proj, proj_range = _thin_projector_bases(np.asarray(design.P_u, dtype=float))
        nbr_idx, nbr_w = _neighbour_lists(adj)
        return cls(
            A=_ro(design.A), B=_ro(design.B), B_v=_ro(B_v), C=_ro(design.C),
            E_bar=_ro(design.E_bar), F_bar=_ro(design.F_bar), G_bar=_ro(design.G_bar),
            B_bar=_ro(design.B_bar), P_u=_ro(design.P_u), laplacian=_ro(lap), A_r=_ro(A_r),
            Q_proj=_ro(Q_proj), proj_range=_ro_bool(proj_range), nbr_idx=_ro_int(nbr_idx), nbr_w=_ro(nbr_w),
            degree=_ro(adj.sum(axis=1)),
            phi=per_node("phi", phi), phi_s=per_node("phi_s", phi_s),
            sigma=per_node("sigma", sigma), sigma_s=per_node("sigma_s", sigma_s),
            S_v=_ro(S), Phi_v=_ro(expm(S * dt)), dt=float(dt), substeps=int(substeps),
            has_reference=K_ref is not None, has_exosystem=exosystem is not None,
        )

    def with_timing(self, dt: float | None = None, substeps: int | None = None) -> "SimParams":
        """Same configuration with another Euler step or control period."""
        dt = self.dt if dt is None else float(dt)
        substeps = self.substeps if substeps is None else int(substeps)
        if substeps < 1 or not dt > 0:
            raise ValueError("dt must be > 0 and substeps >= 1")
        return replace(self, dt=dt, substeps=substeps, Phi_v=_ro(expm(self.S_v * dt)))

    def initial_state(self, x0, *, z0=None, gamma0=0.1, gamma_s0=0.1, v0=None, x_r0=None, t0=0.0) -> SimState:
        """Batched initial state. ``x0`` is (n,) or (B, n); ``z0`` defaults to 0 (paper)."""
        n, N, m_v = self.n_states, self.n_nodes, self.n_unknown
        x0 = as_array(x0, "x0")
        if x0.ndim == 1:
            x0 = x0[None]
        if x0.ndim != 2 or x0.shape[1] != n:
            raise ValueError(f"x0 must have shape ({n},) or (batch, {n}), got {x0.shape}")
        Bsz = x0.shape[0]

        def batched(name, val, shape):
            arr = np.zeros((Bsz,) + shape) if val is None else np.array(np.broadcast_to(np.asarray(val, dtype=float), (Bsz,) + shape))
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{name} contains NaN or inf")
            return np.ascontiguousarray(arr)

        try:
            return SimState(
                t=np.full(Bsz, float(t0)),
                x=np.ascontiguousarray(x0),
                z=batched("z0", z0, (N, n)),
                gamma=batched("gamma0", gamma0, (N,)),
                gamma_s=batched("gamma_s0", gamma_s0, (N,)),
                v=batched("v0", v0, (m_v,)),
                x_r=batched("x_r0", x_r0, (n,)),
            )
        except ValueError as exc:
            if "broadcast" in str(exc):
                raise ValueError(f"initial-state component has the wrong shape: {exc}") from None
            raise
