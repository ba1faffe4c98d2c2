"""State, parameters and static structure of the JAX environments (gymnax style).

Three objects describe one environment configuration:

- :class:`EnvParams`: every number of the configuration (plant, observers, gains, reference, cost
  weights, bounds, reset distribution), a frozen pytree of arrays. It is an argument of every pure
  function, so ``jax.vmap`` runs copies with different parameters (stack several params with
  ``jax.tree.map(lambda *a: jnp.stack(a), *params)``, or ``params.replace(state_bound=...)``).
- :class:`Structure`: what fixes the shapes and the branches of the compiled code (sizes, the
  number of Euler steps per control period, the reward shape, the observation gathers), held by the
  environment object and static under ``jax.jit``.
- :class:`EnvState`: the state of one copy (batch it with ``jax.vmap``): the simulation arrays of
  :class:`dobs_envs.sim.SimState`, the held input, the control-step counter ``time`` (gymnax's name)
  and the parameters of the random disturbance signal.

:func:`from_core` reads all three from a batch-1 :class:`~dobs_envs.envs.env_core.EnvCore`: the options
are validated, the observer designed (Lemma 2, eqs. (barEFGB)/(TidTiu)), the action bound calibrated
and the observation layout built by the same code as the compiled environments, once, in numpy.
"""
from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from ..envs.distributions import DEFAULT_INIT_NOISE
from ..envs.env_core import REWARD_CODES
from .faults import FaultParams, FaultState, FaultStructure, from_fault_args
from .operators import patterns_of

__all__ = ["EnvParams", "EnvState", "Structure", "from_core", "DISTURBANCE_CODES"]

#: ``disturbance`` option -> code of :attr:`Structure.disturbance`
DISTURBANCE_CODES = {"none": 0, "exosystem": 1, "random": 2}


@struct.dataclass
class EnvParams:
    """The numbers of one environment configuration (shapes: ``n`` states, ``N`` observer nodes, ``p``
    the widest output, ``m`` inputs, ``m_v`` unknown inputs).

    Attributes
    ----------
    A (n, n), B (n, m), B_v (n, m_v) : the plant, eq. (LTIsys).
    C (N, p, n) : the nodes' output matrices, eq. (localmeasure), zero-padded to ``p`` rows.
    G_bar (N, n, p), E_bar (N, n, n), F_bar (N, n, p), B_bar (N, n, m) : the observers, eqs. (barEFGB),
        (zidynamic), (hatxieq).
    P_u (N, n, n) : ``T_iu T_iu^T``, the projector of eq. (TidTiu).
    laplacian (N, N), degree (N,) : the O-O graph (``degree`` = the Laplacian's diagonal).
    phi, phi_s, sigma, sigma_s (N,) : the adaptive-gain laws, eqs. (gammaiis)/(gagasbeta).
    gamma0, gamma_s0 (N,) : the gains at reset.
    A_r (n, n) : the reference model ``A + B K`` of eq. (refxdy) (zeros without a reference).
    ref (3, m) : amplitude, frequency and phase of the reference command ``r(t)``.
    Phi_v (m_v, m_v) : ``expm(S dt)``, the exosystem over one Euler step; S (m_v, m_v) itself (reset).
    dt : Euler step (s). The control period is ``dt * Structure.substeps``.
    Q (n, n), R (m, m) : cost weights of ``c = e'Qe + u'Ru``; lam_q = ``lambda_max(Q)``.
    cost_scale : ``c0 = lambda_max(Q) cost_scale^2`` of the log reward.
    action_low, action_high (m,) : the input bounds (inputs are clipped to them).
    action_scale (m,) : action unit -> input (the bound with ``normalized_actions``, else 1).
    state_bound : termination when ``||x|| > state_bound``.
    max_steps_in_episode : truncation after this many control steps (gymnax's name); also the
        horizon the termination penalty charges.
    x0 (n,), x0_scale, init_noise : the reset distribution of ``x`` (module doc of
        :mod:`dobs_envs.envs.distributions`): ``U[-x0_scale, x0_scale]^n`` when
        :attr:`Structure.x0_uniform`, else ``x0 + U[-init_noise, init_noise]^n``.
    v0 (m_v,), disturbance_amplitude : the unknown input's reset.
    x_r0 (n,) : the reference model's initial state.
    faults : the numbers of the communication faults (:class:`~dobs_envs.jax.faults.FaultParams`), or None.
    """

    A: jax.Array
    B: jax.Array
    B_v: jax.Array
    C: jax.Array
    G_bar: jax.Array
    E_bar: jax.Array
    F_bar: jax.Array
    B_bar: jax.Array
    P_u: jax.Array
    laplacian: jax.Array
    degree: jax.Array
    phi: jax.Array
    phi_s: jax.Array
    sigma: jax.Array
    sigma_s: jax.Array
    gamma0: jax.Array
    gamma_s0: jax.Array
    A_r: jax.Array
    ref: jax.Array
    Phi_v: jax.Array
    S: jax.Array
    dt: jax.Array
    Q: jax.Array
    R: jax.Array
    lam_q: jax.Array
    cost_scale: jax.Array
    action_low: jax.Array
    action_high: jax.Array
    action_scale: jax.Array
    state_bound: jax.Array
    max_steps_in_episode: jax.Array
    x0: jax.Array
    x0_scale: jax.Array
    init_noise: jax.Array
    v0: jax.Array
    disturbance_amplitude: jax.Array
    x_r0: jax.Array
    faults: FaultParams | None = None


@struct.dataclass
class EnvState:
    """The state of one copy (``jax.vmap`` adds the batch axis in front of every field).

    Attributes
    ----------
    t : simulated time (s).
    x (n,), z (N, n), gamma (N,), gamma_s (N,), v (m_v,), x_r (n,) : as
        :class:`dobs_envs.sim.SimState` (plant, observer nodes, adaptive gains, unknown input,
        reference model).
    u (m,) : the input applied over the last control period (after clipping; zeros after reset).
    time : control steps since reset (int32).
    sig (3, m_v, L) : amplitudes, frequencies and phases of the ``"random"`` disturbance
        (zeros otherwise).
    fault : the communication faults' state (:class:`~dobs_envs.jax.faults.FaultState`), or None.
    """

    t: jax.Array
    x: jax.Array
    z: jax.Array
    gamma: jax.Array
    gamma_s: jax.Array
    v: jax.Array
    x_r: jax.Array
    u: jax.Array
    time: jax.Array
    sig: jax.Array
    fault: FaultState | None = None


@dataclass(frozen=True, eq=False)
class Structure:
    """What is static under ``jax.jit``: sizes, branches and the observation gathers (numpy arrays).

    Attributes
    ----------
    n, N, m, m_v, p, K : states, observer nodes, inputs, unknown inputs, widest output, agents.
    substeps : Euler steps per control period.
    has_reference : tracking task (``e = x - x_r``, reference model and command).
    reward_code : 0 quadratic, 1 log, 2 sqrt (:data:`dobs_envs.envs.env_core.REWARD_CODES`).
    termination_penalty : charge the bound's cost for the rest of the horizon on termination.
    disturbance : :data:`DISTURBANCE_CODES` of the resolved ``disturbance`` option.
    exosystem : the exosystem matrix is not zero (reset draws a random time shift of ``v``).
    x0_uniform : reset draws ``U[-x0_scale, x0_scale]^n`` (else ``x0`` plus uniform noise).
    y_index (sum p_i,) : positions of the nodes' first ``p_i`` outputs in the flattened ``(N p)`` ``y``.
    feature_size : length ``F`` of the feature vector of :mod:`dobs_envs.envs.observation`.
    padded_index (K, D) : the agents' padded gathers from the feature vector.
    concat_index (sum w_k,) : the agents' observations concatenated, from the flattened ``(K D)``.
    obs_widths (K,) : the agents' true widths; obs_dtype : the observations' dtype.
    action_widths (K,) : the agents' action widths; action_gather (m,) : input ``j``'s position in the
        agents' actions concatenated.
    normalized_actions : agents act in ``[-1, 1]`` (scaled by :attr:`EnvParams.action_scale`).
    task_positions : positions of the rendezvous disagreement (hetero_mas), or None.
    task_error_key : its info key (``"disagreement"``) or None.
    agents : the agents' names; links (K,) : each agent's observer node.
    dtype : the float dtype of the simulation.
    sparse : the products run over the nonzeros of the system's matrices (:mod:`dobs_envs.jax.operators`).
    patterns : those nonzeros (:func:`~dobs_envs.jax.operators.patterns_of`).
    faults : the static part of the communication faults (:class:`~dobs_envs.jax.faults.FaultStructure`),
        or None (``faults=None``: no fault code is traced).
    """

    n: int
    N: int
    m: int
    m_v: int
    p: int
    K: int
    substeps: int
    has_reference: bool
    reward_code: int
    termination_penalty: bool
    disturbance: int
    exosystem: bool
    x0_uniform: bool
    y_index: np.ndarray
    feature_size: int
    padded_index: np.ndarray
    concat_index: np.ndarray
    obs_widths: tuple
    obs_dtype: np.dtype
    action_widths: tuple
    action_gather: np.ndarray
    normalized_actions: bool
    task_positions: np.ndarray | None
    task_error_key: str | None
    agents: tuple
    links: tuple
    dtype: np.dtype
    sparse: bool
    patterns: dict
    faults: FaultStructure | None = None


def from_core(core, *, max_steps_in_episode: int, dtype, sparse: bool = True) -> tuple[Structure, EnvParams]:
    """``(structure, params)`` of a batch-1 :class:`~dobs_envs.envs.env_core.EnvCore` (see module doc).

    ``dtype``: ``jnp.float64`` (needs ``jax_enable_x64``) or ``jnp.float32``; the arrays are built in
    float64 by the numpy design code and cast once here.
    """
    p, sc, L = core.params, core.scenario, core.layout
    n, N, m, m_v = core.n_states, core.n_nodes, core.n_inputs, core.n_unknown
    te = getattr(core, "_task_error", None)
    positions = None
    if te is not None:
        positions = getattr(te, "positions", None)
        if positions is None:
            raise NotImplementedError(f"the task error {type(te).__name__} has no JAX form (only the rendezvous "
                                      f"disagreement of hetero_mas has)")
        positions = np.asarray(positions, dtype=np.intp)
    p_i = [c.shape[0] for c in sc.C]
    pw = p.C.shape[1]
    y_index = np.concatenate([i * pw + np.arange(pi) for i, pi in enumerate(p_i)]).astype(np.intp)
    ref = np.zeros((3, m))
    if core.has_reference:
        ref[0], ref[1], ref[2] = sc.reference.amplitude, sc.reference.frequency, sc.reference.phase
    dist = core.distribution
    fst = fpar = None
    if core.faults is not None:  # the compiled core's resolved fault constants (its links and rates)
        fst, fpar = from_fault_args(core._fa, core.links, n, dtype)
    structure = Structure(
        n=n, N=N, m=m, m_v=m_v, p=pw, K=core.n_agents, substeps=int(core.substeps),
        has_reference=bool(core.has_reference), reward_code=REWARD_CODES[core.reward_kind],
        termination_penalty=bool(core.termination_penalty), disturbance=DISTURBANCE_CODES[core.disturbance],
        exosystem=bool(dist._exo), x0_uniform=dist.init_noise is None and sc.x0_scale is not None,
        y_index=y_index, feature_size=int(L.size), padded_index=np.asarray(L.padded_index, dtype=np.intp),
        concat_index=np.asarray(L.concat_index, dtype=np.intp), obs_widths=tuple(int(w) for w in core.obs_widths),
        obs_dtype=np.dtype(core.obs_dtype), action_widths=tuple(int(w) for w in core.agent_action_widths),
        action_gather=np.asarray(core.action_gather, dtype=np.intp), normalized_actions=bool(core.normalized_actions),
        task_positions=positions, task_error_key=core.task_error_key, agents=tuple(core.agents),
        links=tuple(int(i) for i in core.links), dtype=np.dtype(dtype), sparse=bool(sparse), patterns={},
        faults=fst)
    Q = np.asarray(core.Q, dtype=np.float64)
    lam_q = float(np.linalg.eigvalsh(0.5 * (Q + Q.T))[-1])
    f = lambda a: jnp.asarray(np.asarray(a, dtype=np.float64), dtype=dtype)  # noqa: E731
    per_node = lambda a: f(np.broadcast_to(np.asarray(a, dtype=np.float64), (N,)))  # noqa: E731
    bound = np.asarray(core.action_bound, dtype=np.float64)
    S = np.asarray(sc.exosystem, dtype=np.float64) if sc.exosystem is not None else np.zeros((m_v, m_v))
    if S.shape != (m_v, m_v):
        S = np.zeros((m_v, m_v))
    params = EnvParams(
        A=f(p.A), B=f(p.B), B_v=f(p.B_v), C=f(p.C), G_bar=f(p.G_bar), E_bar=f(p.E_bar), F_bar=f(p.F_bar),
        B_bar=f(p.B_bar), P_u=f(p.P_u), laplacian=f(p.laplacian), degree=f(np.diagonal(p.laplacian)),
        phi=f(p.phi), phi_s=f(p.phi_s), sigma=f(p.sigma), sigma_s=f(p.sigma_s),
        gamma0=per_node(sc.gamma0), gamma_s0=per_node(sc.gamma_s0), A_r=f(p.A_r), ref=f(ref), Phi_v=f(p.Phi_v),
        S=f(S), dt=f(p.dt), Q=f(Q), R=f(core.R), lam_q=f(lam_q), cost_scale=f(core.cost_scale),
        action_low=f(-bound), action_high=f(bound), action_scale=f(core.action_scale),
        state_bound=f(core.state_bound), max_steps_in_episode=jnp.asarray(int(max_steps_in_episode), dtype=jnp.int32),
        x0=f(sc.x0), x0_scale=f(sc.x0_scale if sc.x0_scale is not None else 0.0),
        init_noise=f(DEFAULT_INIT_NOISE if dist.init_noise is None else dist.init_noise),
        v0=f(np.zeros(m_v) if sc.v0 is None else np.reshape(sc.v0, (m_v,))),
        disturbance_amplitude=f(core.disturbance_amplitude),
        x_r0=f(sc.x_r0 if sc.x_r0 is not None else np.zeros(n)), faults=fpar)
    structure.patterns.update(patterns_of(params, sparse=sparse))
    return structure, params
