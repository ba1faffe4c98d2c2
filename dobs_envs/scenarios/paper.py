"""The paper's three numerical examples (Sections NE1, NE2, NE3) and the NE2 ablation.

All matrices, gains, adaptive-law constants and initial conditions are the
printed ones. The O-O graph figures (Figs. MASGraph and LFCGraph) are missing
from the source; we use connected graphs with unit weights (documented per
scenario), which is all Assumption 5 requires.
"""
from __future__ import annotations

import numpy as np

from ..design.gains import shifted_are_feedback, sliding_mode_P
from ..graphs import ring_graph
from .scenario import Scenario
from .composition import compose_mas
from .signals import Sinusoids

__all__ = ["ne1", "ne2", "ne2_ablation", "ne3", "ne2_plant", "ne1_agents", "PAPER_SCENARIOS"]


def _e(n, *idx):
    v = np.zeros(n)
    for i in idx:
        v[i - 1] = 1.0  # the paper's 1-based state indices
    return v


def ne2_plant():
    """NE2's ``A`` (9 x 9), channels ``B^1..B^5`` and outputs ``C_1..C_6`` as printed."""
    n = 9
    A = np.zeros((n, n))
    for (i, j) in [(1, 2), (1, 4), (2, 9), (3, 4), (4, 7), (5, 6), (7, 8), (8, 9)]:
        A[i - 1, j - 1] = 1.0
    channels = [
        _e(n, 2)[:, None],
        _e(n, 4)[:, None],
        _e(n, 1, 5, 6)[:, None],
        _e(n, 3, 9)[:, None],
        _e(n, 1)[:, None],
    ]
    C = [_e(n, k)[None, :] for k in (1, 3, 5, 7, 2, 4)]
    return A, channels, C


def _ne2_like(name, *, description, controller, sliding: bool = False, **overrides):
    """NE2's plant, nodes, graph and links with ``K^k = -(B^k)^T X`` (shifted ARE, ``s = 0.2``); with
    ``sliding=True`` also NE3's ``P``: ``(A + BK)^T P + P (A + BK) = -I``."""
    A, channels, C = ne2_plant()
    B = np.hstack(channels)
    _, K = shifted_are_feedback(A, B, shift=0.2)  # K^k = -(B^k)^T X
    if sliding:
        overrides["P"] = sliding_mode_P(A, B, K)
    base = dict(
        name=name,
        A=A, channels=channels, C=C,
        # observer node i receives u_i = u^i (i = 1..5) and u_6 = u^5 (0-based below)
        known=[(0,), (1,), (2,), (3,), (4,), (4,)],
        # Fig. LFCGraph is missing from the source: a ring 1-2-3-4-5-6-1, unit weights
        graph=ring_graph(6),
        # C-O links: controller k uses observer node k's estimate (u^5 uses xhat_5)
        links=(0, 1, 2, 3, 4),
        K=K,
        controller=controller,
        description=description,
    )
    base.update(overrides)
    return Scenario(**base)


def ne2(*, t_end: float = 20.0, dt: float = 1e-3) -> Scenario:
    """Section NE2: distributed observer-based tracking (Theorem reftrackthm).

    Five controller nodes ``u^k = K^k xhat_k + r^k`` with ``r^k = sin(t + k)``,
    six observer nodes ``y_i = C_i x``; ``K^k = -(B^k)^T X`` with ``X`` from
    ``(A + 0.2 I)^T X + X (A + 0.2 I) - X B B^T X + I = 0``; reference model
    (refxdy) from ``x_r(0) = 0``; ``gamma_i(0) = gamma_is(0) = 0.1``,
    ``phi_i = 0.2``, ``phi_is = 0.5``. O-O graph: ring 1-2-3-4-5-6-1 (unit weights;
    the paper's Fig. LFCGraph is missing from the source).
    """
    return _ne2_like(
        "ne2",
        description=ne2.__doc__.split("\n\n")[0],
        controller="tracking",
        reference=Sinusoids(amplitude=1.0, frequency=1.0, phase=[1, 2, 3, 4, 5]),
        x0=[-1, -2, -3, -4, 5, 4, 3, 2, 1],
        x_r0=np.zeros(9),
        gamma0=0.1, gamma_s0=0.1, phi=0.2, phi_s=0.5,
        t_end=t_end, dt=dt,
    )


def ne2_ablation(*, t_end: float = 20.0, dt: float = 1e-3) -> Scenario:
    """NE2 without the discontinuous consensus term: ``gamma_is(0) = 0``, ``phi_is = 0``.

    The paper (Figs. LFCTrackingError-Coma, LFCEstimationError-Coma) shows that
    neither the tracking nor the estimation errors converge.
    """
    return ne2(t_end=t_end, dt=dt).replace(name="ne2-ablation", gamma_s0=0.0, phi_s=0.0,
                                            description=ne2_ablation.__doc__.split("\n\n")[0])


def ne3(*, t_end: float = 20.0, dt: float = 1e-3, epsilon: float = 0.2) -> Scenario:
    """Section NE3: adaptive boundary-layer sliding-mode stabilisation (Theorem adsmthm).

    Unknown input from the exosystem ``v' = [[0, 0.5], [-0.5, 0]] v``,
    ``v(0) = (-2, 2)``, matched through ``B_v = [B^1 B^2]``; ``P`` from
    ``(A + BK)^T P + P (A + BK) = -I``; ``epsilon = 0.2``; ``beta(0) = 0.1``,
    ``sigma^k = 0.1``, ``phi^k = 5``; ``gamma_i(0) = 0.1``, ``sigma_i = 0.2``,
    ``phi_i = 5``; ``gamma_is(0) = 0.1``, ``sigma_is = 0.1``, ``phi_is = 10``;
    ``x(0) = (1, -1, 1, -1, 1, -1, 1, -1, 1)``. Graph and links as in NE2.
    """
    _, channels, _ = ne2_plant()
    return _ne2_like(
        "ne3",
        description=ne3.__doc__.split("\n\n")[0],
        controller="adaptive_sliding_mode",
        sliding=True,  # P from (A + BK)^T P + P (A + BK) = -I
        B_v=np.hstack([channels[0], channels[1]]),
        exosystem=np.array([[0.0, 0.5], [-0.5, 0.0]]),
        v0=[-2.0, 2.0],
        x0=[1, -1, 1, -1, 1, -1, 1, -1, 1],
        gamma0=0.1, sigma=0.2, phi=5.0,
        gamma_s0=0.1, sigma_s=0.1, phi_s=10.0,
        beta0=0.1, sigma_beta=0.1, phi_beta=5.0, epsilon=epsilon,
        t_end=t_end, dt=dt,
    )


def ne1_agents():
    """The five agents ``(A_i, B_i, C_i)`` of Section NE1 (eq. HMAS)."""
    integ = (np.zeros((1, 1)), np.ones((1, 1)), np.ones((1, 1)))
    dbl = (np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]))
    tri = (np.diag([1.0, 1.0], 1), np.array([[0.0], [0.0], [1.0]]), np.array([[1.0, 0.0, 0.0]]))
    return [integ, integ, dbl, dbl, tri]


def ne1(*, t_end: float = 30.0, dt: float = 1e-3) -> Scenario:
    """Section NE1: heterogeneous MAS, distributed estimation (Theorem HMASthm).

    Five agents (two integrators, two double integrators, one triple integrator)
    with prescribed inputs ``u_i = 0.5 (i-1) sin((6-i) t)``; observer (obidynamicMAS)
    with ``L_i = -X_i C_i^T`` from ``(A_i + 0.2 I) X_i + X_i (A_i + 0.2 I)^T -
    X_i C_i^T C_i X_i + I = 0``; ``gamma_i(0) = gamma_is(0) = 0.1``,
    ``phi_i = 0.2``, ``phi_is = 0.5``. O-O graph: ring 1-2-3-4-5-1 (unit weights;
    Fig. MASGraph is missing from the source).
    """
    return Scenario(
        name="ne1",
        # A = diag(A_i), B^i = [0 B_i^T 0]^T, C_i = [0 C_i 0]; agent i knows u_i and uses xhat_i
        **compose_mas(ne1_agents())._asdict(),
        graph=ring_graph(5),
        x0=[-1, -2, -3, -4, 5, 4, 3, 2, 1],
        prescribed_input=Sinusoids(amplitude=[0.5 * i for i in range(5)], frequency=[5, 4, 3, 2, 1], phase=0.0),
        controller="open_loop",
        gamma0=0.1, gamma_s0=0.1, phi=0.2, phi_s=0.5,
        mas_shift=0.2,
        t_end=t_end, dt=dt,
        description=ne1.__doc__.split("\n\n")[0],
    )


#: name -> factory, the scenarios of ``dobs-envs reproduce``.
PAPER_SCENARIOS = {"ne1": ne1, "ne2": ne2, "ne2-ablation": ne2_ablation, "ne3": ne3}
