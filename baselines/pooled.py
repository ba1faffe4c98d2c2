"""Analytic baselines with exactly the centralised RL agent's information (issue 20, item 4).

The centralised agent (Gymnasium view, e.g. ``gym.make("dobs_envs/Tracking-v0")``) observes
the concatenation of every controller node's ``"local"`` observation: for controller ``k``
with linked observer node ``i = links[k]``, ``y_i`` (component ``"y"``), ``xhat_i``
(``"xhat"``), the estimates ``xhat_j`` of node ``i``'s O-O neighbours (``"neighbors"``, with
``"mask"``) and, for tracking, ``r^k`` (``"r"``). The paper's controller ``k`` acts on
``xhat_{links[k]}`` alone. The policies here pool that information:

- :class:`PooledKalmanPolicy` -- **Kalman filter on the pooled observation + the task's own
  law**. A sampled-data Kalman filter at the control period fuses the pooled measurements and
  the known inputs into one central estimate ``xhat_c``, which replaces the ``"xhat"``
  component of every agent's observation before the scenario's own paper law runs
  (:class:`~baselines.policies.SeparationPolicy`: tracking ``u^k = K^k xhat + r^k``
  (Theorem reftrackthm), adaptive sliding mode (eqs. hepsfunc, adlawbeta), feedback
  ``u^k = K^k xhat`` (eq. linearfeedback), ...), exactly as
  :class:`~baselines.references.OraclePolicy` substitutes the true ``x``.
- :class:`PooledLQGPolicy` -- **LQG on the task's own cost**: the same estimator, and the
  LQ-optimal sampled-data controller for the environment's reward
  ``-(e'Qe + u'Ru) T`` (``e = x - x_r`` or ``x``), with the exogenous signals it can
  reconstruct (reference model ``x_r``, reference command ``r``, unknown input ``v``)
  as feedforward. It answers "what does the cost-optimal analytic controller with the
  centralised agent's information achieve" (issue item 9); it does not use the paper's gains.

Information pattern (both policies)
-----------------------------------
Read every step, through ``env.observation_layout(agent)`` slices only: ``y_i`` of every
linked node (a node linked to several controllers counted once), ``r^k`` (tracking) and,
only where the pooled ``y`` leaves part of the state unobservable, the pooled estimates
``xhat_j`` (``"xhat"``/``"neighbors"``, real slots by the graph, as ``"mask"`` says).
Also used: the policy's own past inputs (the centralised agent chooses all of them; the
clipped value the plant receives), the number of steps since :meth:`reset` (``t = k T``),
and the model: ``A``, ``B^k``, ``C_i``, ``B_v`` and its exosystem ``S``, links, graph,
``K``, ``Q``, ``R``, the simulator's ``dt``/``substeps`` and the documented reset
distribution (``x(0)``, ``v(0)``; the trained agent knows it implicitly). **Never**
``env.state()``, the true ``x``, ``x_r``, ``v``, nor observation components outside
``"local"`` (``"x"``, ``"estimates"``, ...; a ``"full"`` observation is accepted, those
entries are ignored). An observation without ``"y"`` (or ``"r"`` for tracking, or the
estimates the pooled ``y`` cannot replace) is refused with :class:`PooledObservationError`.

Communication faults
--------------------
With the env option ``faults`` (``tracking_lossy_v0``; :mod:`dobs_envs.sim.faults`) the agents observe what
reached them, and so do these policies: ``y_i = C_i x + n_i`` with the sensor noise ``n_i`` of the period
(``measurement_noise``: standard deviation ``sigma_n``, one draw per control period, node and output row, held
over the period, so white from one sample to the next), the reference command ``r^k`` (not faulted), and the
``"xhat"``/``"neighbors"`` estimates as held copies (the C-O estimate delivered last, the O-O copies of the last
broadcast received). The filter takes the sensor noise into its model, ``cov(n_y) = (sigma_y^2 + sigma_n^2) I``
(the documented fault setting is part of the model, as the reset distribution is; the y of the observation is
the one the agent receives); the losses and delays of the links do not enter it, because it reads no estimate:
the pooled ``y`` of every registered env is observable. Where the estimates would be needed (or with
``estimates="all"``) and the env has faults, the filter refuses with :class:`FaultedEstimatesError`: a held
copy is not the current estimate its measurement model assumes, and this baseline does not pretend it is.
So on ``tracking_lossy`` the information column "pooled: every node's obs" stays true: noisy ``y``, ``r``, its own
past inputs, and nothing the agents do not receive. Measured on ``tracking_lossy_v0`` (tuning episodes
20000-20009, 2026-12-03; mean over episodes of J / J_paper on the same faulted episode, then of J over the
paper's cost on ``tracking_v0``, the same episodes): the paper's controller 1 / 1.056, PooledKalman 0.360 /
0.380 (0.380 without faults), PooledLQG 0.319 / 0.337 (0.337), the oracle 0.360 / 0.380 (identical: the true
state). The sensor noise in the model barely changes the estimate's accuracy (RMS error over steps 20-80 of
seed 20003: 0.00559 with it, 0.00562 trusting ``y`` to the rounding: with the small process noise both average
the history) but makes the covariance consistent (NEES ~9 for 9 states instead of ~6e4;
``tests/test_baselines_faults.py``).

Estimator (:class:`PooledKalmanFilter`)
---------------------------------------
State ``s = (x, v)`` (``v`` only when the env has an unknown input that is not
``disturbance="none"``). The simulator integrates eq. (LTIsys) by forward Euler with step
``dt``, ``substeps`` steps per control period ``T`` with the input held (ZOH) and
``v <- expm(S dt) v`` after each step; its exact transition over one period is::

    s_{k+1} = F s_k + G u_k (+ w_k),       F, G = blocks of  M1^substeps,
    M1 = [[I + dt A, dt B_v, dt B], [0, Phi_v, 0], [0, 0, I]],  Phi_v = expm(S dt)

(``discretization="euler"``, default; ``"exact"`` uses the continuous-time transition
``expm(T [[A, B_v, B], [0, S, 0], [0, 0, 0]])`` (Van Loan) instead, O(dt) away from the
simulator). Disturbance models (``disturbance_model``): ``"exosystem"`` (the documented
``v' = S v``; prior mean/covariance of ``v(0) = expm(S tau) v0``, ``tau ~ U[0, 4 pi]``
computed by quadrature), ``"random_walk"`` (``v`` held over a period, ``v_{k+1} = v_k +
w_k``: the ``disturbance="random"`` sums of sinusoids; prior and increment variances from
that documented distribution), ``"constant"``; ``"auto"`` picks the env's. Measurements
at ``t = kT`` (the observation handed to the policy)::

    z_k = [ y_pool ; W^T xhat_j (j in the pooled estimate nodes) ] = H s_k + n_k,
    y_pool = col(C_i x, i in sorted(set(links))),  cov(n_k) = diag(sigma_y^2 I, sigma_e^2 I)

``W`` is an orthonormal basis of the x-part of the unobservable subspace of the pooled
pair ``(F, H_y)`` (orthogonal observability staircase with an explicit tolerance,
:func:`dobs_envs.linalg.subspaces.observability_staircase`); empty (estimates unused) when the
pooled ``y`` is observable, which it is for all four default envs (measured). The observer
error ``e_j = xhat_j - x`` is not white (it decays by Theorem 1); ``sigma_e`` is a design
constant, and only the directions ``y`` cannot see use it, so the ``y``-observable part is
never biased by ``e_j``. The pair must be detectable (checked: eigenvalues of the
unobservable block inside the unit circle by ``1e-9``), else :class:`PooledObservationError`.

Prior: ``x(0)`` mean and covariance of the documented reset distribution
(``x0 + U[-a, a]^n``: mean ``x0``, covariance ``a^2/3 I``; ``U[-s, s]^n``: mean 0,
``s^2/3 I``); the Kalman filter is then the best *linear* estimator of ``x`` given the
pooled history (the uniform prior is not Gaussian). ``sigma_y`` (default ``1e-4``) covers the
float32 rounding of the observations (relative ``6e-8``); the process noise is ``q_x^2 I``
(default ``1e-6``, round-off and, with ``"exact"``, the discretisation mismatch) plus the
disturbance model's. The recursion (time-varying Kalman gain, Joseph-form covariance
update, gains by ``scipy.linalg.solve`` on the innovation covariance; never an explicit
inverse) converges to the steady-state filter of ``solve_discrete_are``.

LQ controller (:class:`PooledLQGPolicy`)
----------------------------------------
Per control period ``x_{k+1} = Ad x_k + Bd u_k + Gd xi_k``, exogenous state
``xi_{k+1} = Phi xi_k`` (``xi`` = ``(x_r, w, v)``: reference model (eq. refxdy, held
``r``), harmonic state ``w`` of the reference command ``r = H_w w`` (``r^k = a_k sin(omega_k
t + phi_k)``), unknown input), error ``e = x - M xi``; the reward charges
``e_{k+1}' Q e_{k+1} + u_k' R u_k`` (times ``T``). The value ``x'P x + 2 x' W xi + ...`` of
the infinite-horizon (average-cost) problem gives::

    P = DARE(Ad, Bd, Q, R),   Hk = R + Bd' P Bd,   Kx = Hk^{-1} Bd' P Ad,   Acl = Ad - Bd Kx,
    W - Acl' W Phi = Acl' P Gd - Q M           (Stein equation; |eig Acl| < 1, |eig Phi| <= 1)
    u_k = -Kx xhat_k - Hk^{-1} Bd' (P Gd + W Phi) xi_k

with ``xhat_k``, ``vhat_k`` from the Kalman filter and ``x_r``, ``w`` reconstructed exactly
from the observed ``r`` history and ``t = kT`` (certainty equivalence: LQG-optimal for the
Gaussian surrogate). If ``(Q^{1/2}, Ad)`` has unobservable modes on the unit circle (the
rendezvous cost of hetero_mas_v0 does not weigh the mean position: the DARE solution leaves
that mode at ``|lambda| = 1 - 3e-9``), ``Q + eps I`` with ``eps = 1e-6 lambda_max(Q)`` is used
(``q_regularization``; the spectral radius must stay ``1e-6`` below 1, which also keeps the
Stein equation well posed). On hetero_mas_v0 this gives the unweighted mean position a time
constant of about 10^3 s: within an episode, the cost-optimal "leave it" behaviour.

Measured (tuning seeds 20000-20019, default env options; J/J_paper per episode: IQM / mean;
transient = cost of the first 2 s; sse = RMS task error over the last 5 s; no failures)::

    env                    paper          oracle (x)           PooledKalman         PooledLQG
    tracking               1 / 1          0.334 / 0.340        0.333 / 0.341        0.296 / 0.302
      transient, sse       1074, 0.029    324, 0.026           324, 0.026           269, 0.41
    disturbance_rejection  1 / 1          0.581 / 0.547        0.584 / 0.549        0.424 / 0.396
      transient, sse       190, 0.30      33.4, 0.22           34.0, 0.22           29.7, 1.12
    hetero_mas             1 / 1          0.627 / 0.630        0.628 / 0.630        0.627 / 0.629
      transient, sse       262, 8.9e-4    195, 1.4e-3          195, 1.4e-3          194, 5.2e-6
    random_network         1 / 1          0.225 / 0.294        0.228 / 0.298        0.222 / 0.289
      transient, sse       8.12, 6.6e-5   1.56, 7.6e-7         1.58, 7.7e-7         1.52, 3.0e-6

The pooled estimate matches the full-state oracle to 0.1-1.5 % of the cost (its error is the
prior's at t = 0 and float32 rounding after a few periods). Tried on the same seeds:
``meas_std`` 1e-7 (identical), 1e-2 (0.1-1 % worse); ``discretization="exact"`` (within
0.2 %); ``estimates="all"`` with constant ``R`` (tracking -0.3 %, disturbance +1.7 %,
hetero +2 %; estimate RMS error 0.14-0.24 instead of 0.05): defaults kept. With
``disturbance="random"`` the random-walk ``v`` model makes PooledLQG worse than the oracle
(0.36 vs 0.32): it is LQ-optimal only for the modelled disturbance.

Calling convention as :mod:`baselines.references`: ``policy = PooledKalmanPolicy(penv)``
on a dobs_envs PettingZoo parallel env, ``policy.reset()`` at every episode start, then
``policy(observations) -> actions``; ``Centralized(gym_env, PooledKalmanPolicy)`` for the
Gymnasium view.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import expm, solve, solve_discrete_are

from dobs_envs.linalg.subspaces import observability_staircase

from .policies import SeparationPolicy
from .references import base_env

__all__ = ["PooledObservationError", "FaultedEstimatesError", "PooledObservation", "PooledKalmanFilter",
           "PooledKalmanPolicy", "PooledLQGPolicy", "sampled_data_model", "lq_tracking_gains"]

#: tolerance on |eigenvalue| of the unobservable block below 1 for detectability
DETECT_TOL = 1e-9
#: margin of the LQ closed loop's spectral radius below 1 (else Q is regularised)
STAB_TOL = 1e-6


class PooledObservationError(ValueError):
    """The observation lacks a component the pooled estimator needs (or the pooled pair is
    not detectable from what the agents observe)."""


class FaultedEstimatesError(PooledObservationError):
    """The pooled estimator would need the observed estimates (``"xhat"``, ``"neighbors"``) of an environment with
    communication faults: there they are copies held since their last delivery (lost or delayed packets), which
    its measurement model (the current estimates, eq. (hatxieq)) does not describe, so it refuses them rather than
    treat a stale value as a current measurement (module doc, "Communication faults")."""


# ---------------------------------------------------------------------------- reading
class PooledObservation:
    """Read-only accessor of the pooled ``"local"`` information of a dobs_envs parallel env.

    Attributes
    ----------
    y_nodes : list of int
        The linked observer nodes ``sorted(set(links))`` whose ``y_i`` is pooled.
    y_src : list of (agent, slice)
        Where each ``y_i`` is read (the first controller linked to node ``i``).
    est_src : dict node -> (agent, slice)
        Where each pooled estimate ``xhat_j`` is read (own ``"xhat"`` first, then
        ``"neighbors"`` slots of real neighbours of the graph).
    r_src : list of (agent, slice)
        Reference command ``r^k`` per agent (tracking; else empty).
    """

    def __init__(self, env, *, need_r: bool):
        e = base_env(env)
        n = int(e.n_states)
        self.agents = list(e.possible_agents)
        links = [int(i) for i in e.links]
        self.y_nodes, self.y_src, self.est_src, self.r_src = [], [], {}, []
        layouts = {a: e.observation_layout(a) for a in self.agents}
        graph = e.scenario.graph
        for a, i in zip(self.agents, links):
            lay = layouts[a]
            if "y" not in lay:
                raise PooledObservationError(
                    f"the pooled estimator reads 'y' from every agent's observation; agent {a!r}'s has {list(lay)}")
            if i not in self.y_nodes:
                self.y_nodes.append(i)
                self.y_src.append((a, lay["y"]))
            if need_r:
                if "r" not in lay:
                    raise PooledObservationError(
                        f"the pooled tracking policy reads 'r' from every agent's observation; agent {a!r}'s has {list(lay)}")
                self.r_src.append((a, lay["r"]))
        for a, i in zip(self.agents, links):  # own estimates first
            lay = layouts[a]
            if "xhat" in lay and i not in self.est_src:
                self.est_src[i] = (a, lay["xhat"])
        for a, i in zip(self.agents, links):
            lay = layouts[a]
            if "neighbors" in lay:
                s0 = lay["neighbors"].start
                for slot, j in enumerate(graph.neighbors(i)):
                    j = int(j)
                    if j not in self.est_src:
                        self.est_src[j] = (a, slice(s0 + slot * n, s0 + (slot + 1) * n))
        order = sorted(range(len(self.y_nodes)), key=lambda q: self.y_nodes[q])
        self.y_nodes = [self.y_nodes[q] for q in order]
        self.y_src = [self.y_src[q] for q in order]
        self.est_nodes = sorted(self.est_src)
        self.C = np.vstack([np.asarray(e.scenario.C[i], dtype=np.float64) for i in self.y_nodes])

    def y(self, observations: dict) -> np.ndarray:
        return np.concatenate([np.asarray(observations[a], dtype=np.float64)[sl] for a, sl in self.y_src])

    def estimates(self, observations: dict) -> np.ndarray:
        """``(len(est_nodes), n)`` pooled estimates."""
        return np.stack([np.asarray(observations[self.est_src[j][0]], dtype=np.float64)[self.est_src[j][1]]
                         for j in self.est_nodes]) if self.est_nodes else np.zeros((0, 0))

    def r(self, observations: dict) -> np.ndarray:
        return np.concatenate([np.asarray(observations[a], dtype=np.float64)[sl] for a, sl in self.r_src])


# ---------------------------------------------------------------------------- model
def _resolve_disturbance(e, model: str) -> str:
    models = ("auto", "exosystem", "random_walk", "constant", "none")
    if model not in models:
        raise ValueError(f"disturbance_model must be one of {models}, got {model!r}")
    if int(e.n_unknown) == 0:
        return "none"
    if model != "auto":
        return model
    if e.disturbance == "none":
        return "none"
    if e.disturbance == "random":
        return "random_walk"
    S = e.scenario.exosystem
    return "exosystem" if S is not None and np.any(S) else "constant"


def sampled_data_model(env, disturbance_model: str = "auto", discretization: str = "euler"):
    """Transition of ``s = (x, v)`` over one control period with the input held.

    Returns
    -------
    F : (n + m_v', n + m_v') ndarray; G : (n + m_v', m) ndarray; model : str (resolved
    disturbance model; ``m_v' = 0`` for ``"none"``).
    """
    e = base_env(env)
    sc = e.scenario
    model = _resolve_disturbance(e, disturbance_model)
    if discretization not in ("euler", "exact"):
        raise ValueError(f"discretization must be 'euler' or 'exact', got {discretization!r}")
    A = np.asarray(sc.A, dtype=np.float64)
    B = np.asarray(sc.B, dtype=np.float64)
    n, m = B.shape
    Bv = np.asarray(sc.B_v, dtype=np.float64) if model != "none" else np.zeros((n, 0))
    mv = Bv.shape[1]
    S = np.zeros((mv, mv))
    if model == "exosystem":
        S = np.asarray(sc.exosystem, dtype=np.float64)
    d = n + mv + m
    dt, T = float(e.dt), float(e.control_period)
    if discretization == "euler":
        M1 = np.eye(d)
        M1[:n, :n] += dt * A
        M1[:n, n:n + mv] = dt * Bv
        M1[:n, n + mv:] = dt * B
        M1[n:n + mv, n:n + mv] = expm(S * dt)
        Mp = np.linalg.matrix_power(M1, int(e.substeps))
    else:
        Mc = np.zeros((d, d))
        Mc[:n, :n], Mc[:n, n:n + mv], Mc[:n, n + mv:] = A, Bv, B
        Mc[n:n + mv, n:n + mv] = S
        Mp = expm(Mc * T)
    s = n + mv
    return Mp[:s, :s].copy(), Mp[:s, s:].copy(), model


def _x0_prior(e):
    """Mean and covariance of the documented initial-state distribution."""
    sc = e.scenario
    n = int(e.n_states)
    if e.init_noise is None and sc.x0_scale is not None:
        return np.zeros(n), (float(sc.x0_scale) ** 2 / 3.0) * np.eye(n)
    from dobs_envs.envs.distributions import DEFAULT_INIT_NOISE

    a = DEFAULT_INIT_NOISE if e.init_noise is None else float(e.init_noise)
    return np.asarray(sc.x0, dtype=np.float64).copy(), (a * a / 3.0) * np.eye(n)


def _v_prior(e, model: str):
    """``(mean, cov, increment cov per period)`` of ``v`` under the env's documented distribution."""
    sc = e.scenario
    mv = int(e.n_unknown)
    if model == "exosystem":
        S = np.asarray(sc.exosystem, dtype=np.float64)
        v0 = np.asarray(sc.v0, dtype=np.float64)
        taus = (np.arange(4000) + 0.5) * (4 * np.pi / 4000)  # midpoint rule over tau ~ U[0, 4 pi]
        E1 = expm(S * (taus[1] - taus[0]))
        V = np.empty((taus.size, mv))
        v = expm(S * taus[0]) @ v0
        for q in range(taus.size):
            V[q] = v
            v = E1 @ v
        mean = V.mean(axis=0)
        return mean, np.cov(V.T, bias=True).reshape(mv, mv), np.zeros((mv, mv))
    if model == "constant":
        return np.asarray(sc.v0, dtype=np.float64).copy(), np.zeros((mv, mv)), np.zeros((mv, mv))
    # "random_walk": v_j = sum_l a_l sin(w_l t + ph_l), w ~ U[0.1, 2], sum_l a_l = amplitude
    # (dobs_envs.envs.distributions): E v = 0, var v_j = E[sum a_l^2] / 2,
    # var of its change over a period ~ E[sum a_l^2] E[w^2] T^2 / 2 (moments by a fixed-seed
    # Monte Carlo of the documented draw; not the env's generator)
    from dobs_envs.envs.distributions import N_RANDOM_TERMS

    A = float(e.disturbance_amplitude)
    u = np.random.default_rng(0).uniform(0.0, 1.0, size=(20000, N_RANDOM_TERMS))
    a = A * u / u.sum(axis=1, keepdims=True)
    s2 = float(np.mean(np.sum(a * a, axis=1)))
    w2 = (2.0 ** 3 - 0.1 ** 3) / (3 * 1.9)
    T = float(e.control_period)
    return np.zeros(mv), 0.5 * s2 * np.eye(mv), 0.5 * s2 * w2 * T * T * np.eye(mv)


# ---------------------------------------------------------------------------- estimator
class PooledKalmanFilter:
    """Sampled-data Kalman filter on the pooled observation (see module docstring).

    Parameters
    ----------
    env : dobs_envs parallel env (or wrapper).
    disturbance_model : "auto" | "exosystem" | "random_walk" | "constant" | "none".
    estimates : "unobservable" (default: pooled estimates measure only the directions the
        pooled ``y`` leaves unobservable), "all" (every direction), "none".
    meas_std : sigma_y (the env's sensor noise of option ``faults`` is added: ``y_variance``); est_std : sigma_e;
        process_std : q_x; discretization : "euler" | "exact".
    need_r : the caller also reads ``r`` (tracking).
    """

    def __init__(self, env, *, disturbance_model="auto", estimates="unobservable", meas_std=1e-4, est_std=0.3,
                 process_std=1e-6, discretization="euler", need_r=False):
        e = base_env(env)
        self.env = e
        if estimates not in ("unobservable", "all", "none"):
            raise ValueError(f"estimates must be 'unobservable', 'all' or 'none', got {estimates!r}")
        self.pool = P = PooledObservation(e, need_r=need_r)
        self.F, self.G, self.model = sampled_data_model(e, disturbance_model, discretization)
        n = int(e.n_states)
        self.n = n
        ns = self.F.shape[0]
        self.mv = ns - n
        Hy = np.hstack([P.C, np.zeros((P.C.shape[0], self.mv))])
        self.Hy = Hy
        U, r_o = observability_staircase(self.F, Hy)
        self.observable_dim = int(r_o)
        if estimates == "all":
            W = np.eye(n)
        elif estimates == "unobservable" and r_o < ns:
            Vx = U[:n, r_o:]
            Uw, sw, _ = np.linalg.svd(Vx, full_matrices=False)
            W = Uw[:, sw > 1e-9]
        else:
            W = np.zeros((n, 0))
        self.W = W
        #: the environment's communication faults (a :class:`~dobs_envs.sim.faults.Faults`) or None
        self.faults = faults = e.options.faults
        if W.shape[1] and faults is not None:
            why = ("estimates='all' asks for them" if estimates == "all" else
                   f"the pooled y leaves {ns - r_o} state direction(s) unobservable")
            raise FaultedEstimatesError(
                f"the pooled estimator would use the observed estimates ({why}), but this environment has "
                f"communication faults: they are held copies (stale after a lost or delayed packet), which the "
                f"estimator does not model; use estimates='none' if the pooled y is detectable")
        if W.shape[1]:
            missing = [a for a in P.agents if "xhat" not in e.observation_layout(a)]
            if not P.est_nodes or missing:
                raise PooledObservationError(
                    f"the pooled y leaves {ns - r_o} state direction(s) unobservable; the estimator then needs the "
                    f"pooled estimates ('xhat', 'neighbors'), missing in agent(s) {missing or P.agents}")
        ne = len(P.est_nodes) if W.shape[1] else 0
        Hx = np.vstack([W.T] * ne) if ne else np.zeros((0, n))
        self.H = np.vstack([Hy, np.hstack([Hx, np.zeros((Hx.shape[0], self.mv))])])
        # the documented sensor noise of the fault setting (white across control periods: one draw per period,
        # node and output row, held over the period; the observed y_i = C_i x + n_i at the boundary)
        noise = 0.0 if faults is None else float(faults.measurement_noise)
        #: the variance of every pooled y entry the filter assumes: rounding (meas_std) plus the sensor noise
        self.y_variance = meas_std ** 2 + noise ** 2
        self.R = np.diag(np.concatenate([np.full(Hy.shape[0], self.y_variance), np.full(Hx.shape[0], est_std ** 2)]))
        # detectability of the pair actually used
        U2, r2 = observability_staircase(self.F, self.H)
        if r2 < ns:
            Mu = (U2.T @ self.F @ U2)[r2:, r2:]
            rad = float(np.max(np.abs(np.linalg.eigvals(Mu))))
            if rad >= 1.0 - DETECT_TOL:
                raise PooledObservationError(
                    f"the pooled observation is not detectable: an unobservable mode with |lambda| = {rad:.6g} >= 1 "
                    f"(pooled nodes {P.y_nodes}, estimates {'used' if ne else 'unused'})")
        x_m, x_P = _x0_prior(e)
        Qp = (process_std ** 2) * np.eye(ns)
        # forget past pooled estimates in the directions only they measure: e_j is strongly
        # autocorrelated and decays (Theorem 1), so the newest xhat_j is the information, not an
        # average over the history (random walk of variance sigma_e^2 per period: Kalman gain ~0.6)
        Qp[:n, :n] += (est_std ** 2) * (W @ W.T)
        if self.mv:
            v_m, v_P, v_Q = _v_prior(e, self.model)
            self.m0 = np.concatenate([x_m, v_m])
            self.P0 = np.zeros((ns, ns))
            self.P0[:n, :n], self.P0[n:, n:] = x_P, v_P
            Qp[n:, n:] += v_Q
        else:
            self.m0, self.P0 = x_m, x_P
        self.P0 = self.P0 + (process_std ** 2) * np.eye(ns)
        self.Qp = Qp
        self.reset()

    def reset(self) -> None:
        self.s = None
        self.P = None

    def update(self, observations: dict, u_prev) -> np.ndarray:
        """Predict with the held input ``u_prev`` (None at the first step: the prior), then
        correct with the pooled measurements of ``observations``. Returns ``shat (n + m_v',)``."""
        if self.s is None:
            s, P = self.m0.copy(), self.P0.copy()
        else:
            s = self.F @ self.s + self.G @ np.asarray(u_prev, dtype=np.float64)
            P = self.F @ self.P @ self.F.T + self.Qp
        z = self.pool.y(observations)
        if self.W.shape[1]:
            est = self.pool.estimates(observations)
            z = np.concatenate([z, (est @ self.W).reshape(-1)])
        H, R = self.H, self.R
        PHt = P @ H.T
        Sm = H @ PHt + R
        Sm = 0.5 * (Sm + Sm.T)
        K = solve(Sm, PHt.T, assume_a="pos").T
        s = s + K @ (z - H @ s)
        IKH = np.eye(P.shape[0]) - K @ H
        P = IKH @ P @ IKH.T + K @ R @ K.T
        self.s, self.P = s, 0.5 * (P + P.T)
        return s.copy()

    @property
    def x(self) -> np.ndarray:
        return self.s[:self.n].copy()

    @property
    def v(self) -> np.ndarray:
        return self.s[self.n:].copy()


# ---------------------------------------------------------------------------- policies
class _PooledBase:
    information = "pooled over all controller nodes' local observations (y, estimates, r) + own past inputs"

    def __init__(self, env, *, need_r, estimator_kwargs):
        self.env = e = base_env(env)
        self.agents = list(e.possible_agents)
        self.period = float(e.control_period)
        self.filter = PooledKalmanFilter(e, need_r=need_r, **(estimator_kwargs or {}))
        self._bound = np.broadcast_to(np.asarray(e.action_bound, dtype=np.float64), (int(e.n_inputs),)).copy()
        #: estimate each controller acted on at the last call (agent -> (n,)), as references.py
        self.estimates: dict = {}

    def reset(self) -> None:
        self.filter.reset()
        self._u = None
        self._steps = 0
        self.estimates = {}

    def _emit(self, u) -> dict:
        u = np.clip(np.asarray(u, dtype=np.float64).reshape(-1), -self._bound, self._bound)  # what the plant gets
        self._u = u
        self._steps += 1
        return self.env.actions_from_inputs(u)


class PooledKalmanPolicy(_PooledBase):
    """Kalman filter on the centralised agent's pooled observation + the task's own paper law.

    The central estimate ``xhat_c`` (:class:`PooledKalmanFilter`) replaces the ``"xhat"``
    component of every agent's observation; the scenario's law
    (:class:`~baselines.policies.SeparationPolicy` of ``kind``, default the scenario's
    controller) then acts unchanged (tracking: ``u^k = K^k xhat_c + r^k``, eq. refxdy /
    Theorem reftrackthm; stabilisation: adaptive sliding mode, eqs. hepsfunc and adlawbeta;
    rendezvous / feedback: ``u^k = K^k xhat_c``, eq. linearfeedback).

    Parameters
    ----------
    env : dobs_envs PettingZoo parallel env (or wrapper); ``"local"`` or a superset observation.
    kind : law of :class:`~baselines.policies.SeparationPolicy` (default the scenario's).
    **estimator_kwargs : :class:`PooledKalmanFilter` options (``disturbance_model``,
        ``estimates``, ``meas_std``, ``est_std``, ``process_std``, ``discretization``).
    """

    name = "Kalman on pooled obs + paper law"

    def __init__(self, env, kind=None, **estimator_kwargs):
        e = base_env(env)
        self.inner = SeparationPolicy(e, kind)
        self.kind = self.inner.kind
        if self.kind == "open_loop":
            raise ValueError("the pooled estimate has no use for the open-loop law; choose a feedback law")
        super().__init__(e, need_r=False, estimator_kwargs=estimator_kwargs)
        self._xhat = {a: e.observation_layout(a)["xhat"] for a in self.agents}
        self.reset()

    def reset(self) -> None:
        super().reset()
        self.inner.reset()

    def __call__(self, observations: dict) -> dict:
        x = self.filter.update(observations, self._u)[:self.filter.n]
        obs = {}
        for a in self.agents:
            o = np.array(observations[a], dtype=np.float64, copy=True)
            o[self._xhat[a]] = x
            obs[a] = o
        self.estimates = {a: x.copy() for a in self.agents}
        acts = self._emit(self.inner.inputs(obs))
        return {a: acts[a] for a in observations}


def lq_tracking_gains(Ad, Bd, Gd, Phi, M, Q, R):
    """Average-cost LQ gains for ``x+ = Ad x + Bd u + Gd xi``, ``xi+ = Phi xi``, stage cost
    ``(x+ - M xi+)' Q (x+ - M xi+) + u' R u``: ``u = -Kx x - Kxi xi`` (module docstring).

    Returns ``(Kx, Kxi, P)``; raises ``numpy.linalg.LinAlgError`` if the DARE has no
    stabilising solution.
    """
    P = solve_discrete_are(Ad, Bd, Q, R)
    Hk = R + Bd.T @ P @ Bd
    Kx = solve(Hk, Bd.T @ P @ Ad, assume_a="pos")
    Acl = Ad - Bd @ Kx
    rad = float(np.max(np.abs(np.linalg.eigvals(Acl))))
    if rad >= 1.0 - STAB_TOL:  # e.g. a mode the cost does not weigh, left on the unit circle
        raise np.linalg.LinAlgError(f"the DARE solution does not stabilise (Ad, Bd): spectral radius {rad:.12g} "
                                    f">= 1 - {STAB_TOL:g}")
    nx, nxi = Ad.shape[0], Phi.shape[0]
    if nxi == 0:
        return Kx, np.zeros((Bd.shape[1], 0)), P
    rhs = Acl.T @ P @ Gd - Q @ M
    L = np.eye(nx * nxi) - np.kron(Phi.T, Acl.T)  # vec(Acl' W Phi) = (Phi' kron Acl') vec(W)
    Wm = solve(L, rhs.reshape(-1, order="F")).reshape(nx, nxi, order="F")
    Kxi = solve(Hk, Bd.T @ (P @ Gd + Wm @ Phi), assume_a="pos")
    return Kx, Kxi, P


def _reference_exosystem(sc, T):
    """Harmonic state ``w`` of the reference command: ``r(t) = H_w w(t)``,
    ``w = col(sin(omega t), cos(omega t))`` per distinct frequency; ``(H_w, Phi_w(T), omegas)``."""
    ref = sc.reference
    a, om, ph = (np.asarray(v, dtype=np.float64) for v in (ref.amplitude, ref.frequency, ref.phase))
    omegas = sorted(set(om.tolist()))
    m = a.size
    Hw = np.zeros((m, 2 * len(omegas)))
    Phi = np.zeros((2 * len(omegas), 2 * len(omegas)))
    for q, w in enumerate(omegas):
        sel = om == w
        Hw[sel, 2 * q] = a[sel] * np.cos(ph[sel])  # a sin(wt + ph) = a cos(ph) sin(wt) + a sin(ph) cos(wt)
        Hw[sel, 2 * q + 1] = a[sel] * np.sin(ph[sel])
        c, s = np.cos(w * T), np.sin(w * T)
        Phi[2 * q:2 * q + 2, 2 * q:2 * q + 2] = [[c, s], [-s, c]]
    return Hw, Phi, np.array(omegas)


class PooledLQGPolicy(_PooledBase):
    """LQG on the task's own sampled-data cost with the centralised agent's information.

    The :class:`PooledKalmanFilter` estimate (``xhat``, ``vhat``) feeds the average-cost
    LQ-optimal controller of the environment's reward ``-(e'Qe + u'Ru) T`` (``Q``, ``R`` the
    env's): ``u = -Kx xhat - Kxi xi`` with the exogenous state ``xi = (x_r, w, vhat)``
    (tracking: reference model of eq. refxdy rebuilt from the observed ``r^k`` with
    ``x_r(0)`` the scenario's (0), ``w`` the harmonic state of ``r`` at ``t = kT``). See
    :func:`lq_tracking_gains` and the module docstring. Does not use the paper's ``K``
    except inside the reference model ``x_r' = (A + BK) x_r + B r`` that defines the task.

    Parameters
    ----------
    env : dobs_envs PettingZoo parallel env (or wrapper).
    q_regularization : None (add ``1e-6 lambda_max(Q) I`` only if the DARE has no stabilising
        solution) or a float ``eps`` (``Q + eps I``).
    **estimator_kwargs : :class:`PooledKalmanFilter` options.
    """

    name = "LQG on pooled obs (task's Q, R)"

    def __init__(self, env, q_regularization=None, **estimator_kwargs):
        e = base_env(env)
        sc = e.scenario
        self.tracking = bool(e.has_reference)
        super().__init__(e, need_r=self.tracking, estimator_kwargs=estimator_kwargs)
        f = self.filter
        n, mv, T = f.n, f.mv, self.period
        Ad, Bd = f.F[:n, :n], f.G[:n]
        Gv, Phiv = f.F[:n, n:], f.F[n:, n:]
        Q, R = np.asarray(e.Q, dtype=np.float64), np.asarray(e.R, dtype=np.float64)
        blocks_G, blocks_Phi, blocks_M = [], [], []
        if self.tracking:
            # reference model (Euler, r held over the period): x_r+ = Ar x_r + Br r, r = Hw w
            K = np.asarray(sc.K, dtype=np.float64)
            B = np.asarray(sc.B, dtype=np.float64)
            m = B.shape[1]
            dt, ss = float(e.dt), int(e.substeps)
            M1 = np.eye(n + m)
            M1[:n, :n] += dt * (np.asarray(sc.A) + B @ K)
            M1[:n, n:] = dt * B
            Mp = np.linalg.matrix_power(M1, ss)
            self._Ar, self._Br = Mp[:n, :n].copy(), Mp[:n, n:].copy()
            self._Hw, Phiw, self._omegas = _reference_exosystem(sc, T)
            nw = Phiw.shape[0]
            Phir = np.block([[self._Ar, self._Br @ self._Hw], [np.zeros((nw, n)), Phiw]])
            blocks_Phi.append(Phir)
            blocks_G.append(np.zeros((n, n + nw)))
            blocks_M.append(np.hstack([np.eye(n), np.zeros((n, nw))]))
            self._xr0 = np.asarray(sc.x_r0, dtype=np.float64) if sc.x_r0 is not None else np.zeros(n)
        if mv:
            blocks_Phi.append(Phiv)
            blocks_G.append(Gv)
            blocks_M.append(np.zeros((n, mv)))
        nxi = sum(b.shape[0] for b in blocks_Phi)
        Phi = np.zeros((nxi, nxi))
        o = 0
        for b in blocks_Phi:
            Phi[o:o + b.shape[0], o:o + b.shape[0]] = b
            o += b.shape[0]
        Gd = np.hstack(blocks_G) if blocks_G else np.zeros((n, 0))
        M = np.hstack(blocks_M) if blocks_M else np.zeros((n, 0))
        self.q_regularization = q_regularization
        if q_regularization is None:
            try:
                gains = lq_tracking_gains(Ad, Bd, Gd, Phi, M, Q, R)
                self.q_regularization = 0.0
            except (np.linalg.LinAlgError, ValueError):
                self.q_regularization = 1e-6 * float(np.max(np.linalg.eigvalsh(Q)))
        if self.q_regularization:
            Qr = Q + self.q_regularization * np.eye(n)
            gains = lq_tracking_gains(Ad, Bd, Gd, Phi, M, Qr, R)
        self.Kx, self.Kxi, self.P_lq = gains
        self.reset()

    def reset(self) -> None:
        super().reset()
        self._xr = self._xr0.copy() if self.tracking else None
        self._r_prev = None

    def _xi(self, observations, vhat) -> np.ndarray:
        parts = []
        if self.tracking:
            r = self.filter.pool.r(observations)
            if self._r_prev is not None:
                self._xr = self._Ar @ self._xr + self._Br @ self._r_prev
            self._r_prev = r
            t = self._steps * self.period
            w = np.concatenate([[np.sin(om * t), np.cos(om * t)] for om in self._omegas])
            parts += [self._xr, w]
        if vhat.size:
            parts.append(vhat)
        return np.concatenate(parts) if parts else np.zeros(0)

    def __call__(self, observations: dict) -> dict:
        s = self.filter.update(observations, self._u)
        n = self.filter.n
        x, v = s[:n], s[n:]
        xi = self._xi(observations, v)
        self.estimates = {a: x.copy() for a in self.agents}
        acts = self._emit(-self.Kx @ x - self.Kxi @ xi)
        return {a: acts[a] for a in observations}
