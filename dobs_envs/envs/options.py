"""The options of the environments: one frozen, validated dataclass per environment class.

:class:`EnvOptions` is the single list of the options every environment accepts, with
their defaults; environments with task parameters extend it (:class:`HeteroMASOptions`,
:class:`RandomNetworkOptions`). The dataclass fields *are* the keyword arguments of
the environment classes, of ``tracking_v0.parallel_env(...)``, of ``gym.make`` /
``gym.make_vec`` and of the batched core (the class docstrings' ``## Arguments``
lists are tested against them). Building an options object validates every option
that does not depend on the system (types, ranges, names); the environment core
checks the rest (matrix shapes against the scenario, ``disturbance`` against ``B_v``).

An unknown keyword raises ``TypeError`` worded as Python's own, followed by the valid
names: ``TrackingEnv.__init__() got an unexpected keyword argument 'substep'; valid
arguments are: [...]``.
"""
from __future__ import annotations

import os
from dataclasses import MISSING, dataclass, fields, replace
from typing import Any

import numpy as np

from ..linalg.validation import NUMERIC_KINDS, as_flag, as_float, as_int, check_seed
from ..scenarios.random import GRAPH_TOPOLOGIES, MAX_SIZE
from ..sim.faults import Faults

__all__ = ["EnvOptions", "HeteroMASOptions", "RandomNetworkOptions", "REWARDS", "DISTURBANCES", "RENDER_MODES",
           "StateBoundError", "state_bound_limit", "check_state_bound"]

#: reward shapes of the ``reward`` option
REWARDS = ("quadratic", "log", "sqrt")
#: unknown-input signals of the ``disturbance`` option
DISTURBANCES = ("exosystem", "random", "none")
#: render modes of every environment ("human": a live matplotlib window, see dobs_envs.envs.rendering)
RENDER_MODES = ("human", "rgb_array")

class StateBoundError(ValueError):
    """``state_bound`` above the largest bound for which the simulation of the system is shown finite
    (:func:`state_bound_limit`); the message names the option, the environment and the limit."""


def state_bound_limit(params, gamma0: float, action_bound) -> float:
    """The largest ``state_bound`` for which the environment promises a finite simulation from every state
    inside it, with any inputs inside the action bounds (tested in ``tests/test_bounded_states.py`` up to
    this limit, worst-case directions and extreme actions). Computed from the system (``params``: the
    :class:`~dobs_envs.sim.state.SimParams` of the core; ``gamma0``: the observers' initial gain;
    ``action_bound``: the ``(m,)`` input bounds).

    The integration fails only when an Euler step must be shorter than ``h_min = dt / MAX_SPLIT`` to stay
    monotone (:mod:`dobs_envs.sim.period_kernel`, "Stable steps": ``2 deg_i h (gamma_i + h phi_i
    ||eps_iu||^2) <= 1``), i.e. once a gain exceeds ``1 / (2 deg_i h_min)``. In the consensus coordinates the
    error decays at least at rate ``c gamma`` while the gain grows by ``phi ||eps||^2`` (eq. (gammaiis)), so
    ``gamma^2 + (phi / c) ||eps||^2`` does not grow and the gain peaks below ``sqrt(gamma0^2 + (phi / c)
    E^2)`` for an error ``E``; ``c`` is the smallest positive eigenvalue of ``T_u^T (L x I_n) T_u`` (eq.
    (dotepsu)) and ``||eps_iu|| <= 2 deg_i ||x||``. Inside a control period of length ``T`` the plant grows
    by at most ``exp(||A||_2 T)``, plus ``T ||B||_2 ||u||`` from the inputs, before the bound is checked. Hence

        ``E = min_i sqrt((1 / (2 deg_i h_min))^2 - gamma0^2) sqrt(c / phi_i) / (2 deg_i)``,
        ``limit = E / exp(||A||_2 T) - T ||B||_2 ||action_bound||_2``

    (at most 0 when no state bound is safe, e.g. inputs of 1e30; inf for a system without consensus terms). The argument neglects the coupling through ``Ebar`` and the
    plant, which is why the property test checks the whole range; the registered environments reached
    ``non_finite_state`` from 6.5 (tracking) to 4000 (hetero_mas) times their limit (measured thresholds in
    ``tests/test_bounded_states.py``'s module doc)."""
    from ..sim.period_kernel import MAX_SPLIT

    N, n = params.n_nodes, params.n_states
    lap = np.zeros((N, N))
    for i in range(N):
        for j, w in zip(params.nbr_idx[i], params.nbr_w[i]):
            if w != 0.0:
                lap[i, j] -= w
                lap[i, i] += w
    bases = []
    for i in range(N):  # an orthonormal basis of Im T_iu = Im P_u,i
        w, V = np.linalg.eigh(0.5 * (params.P_u[i] + params.P_u[i].T))
        bases.append(V[:, w > 0.5])
    r = [b.shape[1] for b in bases]
    Tu = np.zeros((N * n, sum(r)))
    for i, b in enumerate(bases):
        Tu[i * n:(i + 1) * n, sum(r[:i]):sum(r[:i + 1])] = b
    ev = np.linalg.eigvalsh(Tu.T @ np.kron(lap, np.eye(n)) @ Tu) if Tu.size else np.zeros(0)
    tol = max(ev.max(initial=0.0), 1.0) * 1e-9
    pos = ev[ev > tol]
    deg, phi = np.asarray(params.degree, dtype=float), np.asarray(params.phi, dtype=float)
    h_min = params.dt / MAX_SPLIT
    growth = float(np.exp(np.linalg.norm(params.A, 2) * params.dt * params.substeps))
    limits = []
    for i in range(N):
        if deg[i] <= 0.0:
            continue  # a node without neighbours has no consensus term: no step test
        g_max = 1.0 / (2.0 * deg[i] * h_min)
        if phi[i] <= 0.0 or pos.size == 0:
            limits.append(np.inf if g_max > gamma0 else 0.0)
            continue
        head = np.sqrt(max(g_max ** 2 - float(gamma0) ** 2, 0.0))
        limits.append(head * np.sqrt(pos.min() / phi[i]) / (2.0 * deg[i]))
    E = float(min(limits, default=np.inf))
    u = float(np.linalg.norm(np.asarray(action_bound, dtype=float)))
    return E / growth - params.dt * params.substeps * float(np.linalg.norm(params.B, 2)) * u


def check_state_bound(state_bound: float, limit: float, env: str) -> None:
    """:class:`StateBoundError` when ``state_bound`` exceeds ``limit`` (:func:`state_bound_limit`) for ``env``
    (an environment class's name, or ``scenario '<name>'``)."""
    if state_bound > limit:
        if limit <= 0:
            raise StateBoundError(f"state_bound={state_bound:g}: no state bound of {env} is shown to keep its "
                                  f"simulation finite with inputs this large (action_bound too large: limit "
                                  f"{limit:.4g}, dobs_envs.envs.options.state_bound_limit); give a smaller "
                                  f"action_bound")
        raise StateBoundError(f"state_bound={state_bound:g} exceeds the limit {limit:.4g} of {env} (the largest bound "
                              f"from which its simulation is shown finite with its action_bound: "
                              f"dobs_envs.envs.options.state_bound_limit); give state_bound <= {limit:.4g}")


@dataclass(frozen=True, eq=False)
class EnvOptions:
    """Options of every environment (defaults; ``None``: "see the environment docstring").

    Attributes
    ----------
    scenario : Scenario, str or path, optional
        The system (a :class:`~dobs_envs.scenarios.scenario.Scenario` or a YAML/JSON file);
        ``None``: the environment's default.
    dt : float
        Euler step (s) of the simulation.
    substeps : int
        Euler steps per control step (inputs held, ZOH); control period ``dt * substeps``.
    max_cycles : int, optional
        Truncation after this many control steps; excludes ``horizon``.
    horizon : float, optional
        Truncation horizon in seconds (``math.inf``: never truncate); ``None`` with
        ``max_cycles=None``: the scenario's ``t_end``.
    observation : str or sequence of str
        ``"local"``, ``"full"`` or component names (:mod:`dobs_envs.envs.observation`).
    obs_dtype : str
        ``"float32"`` or ``"float64"``.
    Q, R : array_like, optional
        Cost weights (``None``: the scenario's): ``Q`` (n, n) symmetric positive semidefinite,
        ``R`` (m, m) symmetric positive definite (checked by the core, as the Scenario checks its own).
    action_bound : float, array_like (m,) or "auto", optional
        Per input component (``None``: the environment's default).
    init_noise : float, optional
        Half-width of the uniform noise added to ``x0`` at reset (``None``: the
        scenario's ``x0_scale`` distribution if it has one, else 1.0).
    state_bound : float
        Termination when ``||x|| > state_bound``; at most the system's limit (:func:`state_bound_limit`,
        checked by the core: :class:`StateBoundError`), below which the simulation is finite.
    termination_penalty : bool
        Charge the cost of the bound for the rest of the horizon on termination.
    reward : str
        ``"quadratic"`` (``c``), ``"log"`` (``log(1 + c / c0)``) or ``"sqrt"`` (``sqrt(c)``).
    cost_scale : float
        Error norm ``c0 = lambda_max(Q) cost_scale^2`` of the log reward.
    render_mode : str, optional
        ``None``, ``"rgb_array"`` (``render()`` returns the error plot as an image) or ``"human"``
        (a live matplotlib window of the error plot, redrawn by ``reset``/``step``; on a machine
        without a display one warning and nothing shown).
    disturbance : str
        ``"exosystem"``, ``"random"`` or ``"none"`` (systems with an unknown input only).
    disturbance_amplitude : float
        Bound of the ``"random"`` disturbance.
    normalized_actions : bool
        Every agent's action space is ``Box(-1, 1, (M,), float32)``, ``M`` the largest number of
        input channels of any agent: entry ``j < m_k`` of agent ``k``'s action is mapped onto
        its channel's bound (``u = a * action_bound``, out-of-range values clipped), entries
        ``j >= m_k`` are ignored. The centralised views (``gym.make``, ``gym.make_vec``) then
        take ``Box(-1, 1, (m,))`` (all inputs stacked, each scaled by its bound; no padding).
    padded_observations : bool
        Identical observation spaces: where the agents' widths differ, every agent observes ``2 W``
        values (``W`` the widest agent observation): its own observation zero-padded to ``W``, then
        a 0/1 mask of ``W`` entries (1 = real entry; component ``"obs_mask"`` of
        ``observation_layout``); where every agent already has width ``W``, its observation as it
        is (no padding, no mask). Either way the same bounds for every agent (the union). With ``normalized_actions`` every agent has identical spaces: one shared policy
        (parameter sharing in SuperSuit, RLlib, BenchMARL, TorchRL) needs no wrapper.
    faults : dict or Faults, optional
        Communication faults and sensor noise (issue 23): ``None`` (default) the paper's ideal links,
        no fault code runs; a dict with the keys ``oo_period``, ``oo_loss``, ``oo_burst``,
        ``oo_delay``, ``co_loss``, ``co_delay``, ``switching``, ``measurement_noise`` or a
        :class:`~dobs_envs.sim.faults.Faults` (semantics there). Stored as a ``Faults`` (or None);
        unknown keys raise ``TypeError``, bad values ``ValueError`` naming ``faults: <key>``.
    """

    scenario: Any = None
    dt: float = 1e-3
    substeps: int = 50
    max_cycles: int | None = None
    horizon: float | None = None
    observation: Any = "local"
    obs_dtype: str = "float32"
    Q: Any = None
    R: Any = None
    action_bound: Any = None
    init_noise: float | None = None
    state_bound: float = 1e3
    termination_penalty: bool = True
    reward: str = "quadratic"
    cost_scale: float = 0.1
    render_mode: str | None = None
    disturbance: str = "exosystem"
    disturbance_amplitude: float = 2.0
    normalized_actions: bool = False
    padded_observations: bool = False
    faults: Any = None

    # ------------------------------------------------------------------ construction
    @classmethod
    def names(cls) -> tuple:
        """Option names, in declaration order."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def defaults(cls) -> dict:
        """``{name: default}`` of every option."""
        return {f.name: (f.default if f.default is not MISSING else f.default_factory()) for f in fields(cls)}

    @classmethod
    def from_kwargs(cls, owner: str, kwargs: dict, *, reject: tuple = ()) -> "EnvOptions":
        """The options of ``owner`` (a class name, for the error message) from keyword arguments.

        Raises ``TypeError`` worded as Python's for the first unknown (or ``reject``-ed) name,
        followed by the valid names, and ``ValueError`` naming the first invalid option.
        """
        valid = [n for n in cls.names() if n not in reject]
        for k in kwargs:
            if k not in valid:
                raise TypeError(f"{owner}.__init__() got an unexpected keyword argument {k!r}; "
                                f"valid arguments are: {sorted(valid)}")
        return cls(**kwargs)

    def replace(self, **changes) -> "EnvOptions":
        """A validated copy with ``changes``."""
        return replace(self, **changes)

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        if isinstance(self.scenario, os.PathLike):
            set_("scenario", os.fspath(self.scenario))
        set_("dt", as_float(self.dt, "dt", positive=True))
        set_("substeps", as_int(self.substeps, "substeps", minimum=1))
        mc, hz = self.max_cycles, self.horizon
        if mc is not None and hz is not None:
            raise ValueError("give either max_cycles (control steps) or horizon (seconds), not both")
        if mc is not None:
            set_("max_cycles", as_int(mc, "max_cycles", minimum=1))
        if hz is not None:
            set_("horizon", as_float(hz, "horizon (seconds; math.inf: never truncate)", positive=True, allow_inf=True))
        try:  # np.dtype(None) is float64: None is refused, not taken as a default
            dtype = np.dtype(self.obs_dtype) if self.obs_dtype is not None else None
        except TypeError:
            dtype = None
        if dtype not in (np.float32, np.float64):
            raise ValueError(f"obs_dtype must be 'float32' or 'float64', got {self.obs_dtype!r}")
        set_("obs_dtype", dtype.name)
        if not isinstance(self.observation, str):
            try:
                set_("observation", tuple(self.observation))
            except TypeError:
                raise ValueError(f"observation must be 'local', 'full' or a sequence of component names, "
                                 f"got {self.observation!r}") from None
        ab = self.action_bound
        if isinstance(ab, str):
            if ab != "auto":
                raise ValueError(f"action_bound must be a number, an array (one per input component) or 'auto', "
                                 f"got {ab!r}")
        elif ab is not None:
            try:
                arr = np.asarray(ab)
            except (TypeError, ValueError):  # ragged sequences
                arr = np.array(np.nan)
            # bool and complex are refused (not cast to 1.0 / the real part)
            arr = arr.astype(np.float64) if arr.dtype.kind in NUMERIC_KINDS else np.array(np.nan)
            if arr.ndim > 1 or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
                raise ValueError(f"action_bound must be a positive finite real number or one per input component, "
                                 f"got {ab!r}")
            arr.flags.writeable = False
            set_("action_bound", float(arr) if arr.ndim == 0 else arr)
        if self.init_noise is not None:
            set_("init_noise", as_float(self.init_noise, "init_noise", minimum=0.0))
        # at most 1e150: its square enters the termination penalty
        set_("state_bound", as_float(self.state_bound, "state_bound", positive=True, maximum=1e150))
        set_("termination_penalty", as_flag(self.termination_penalty, "termination_penalty"))  # "no" is not True
        if not isinstance(self.reward, str) or self.reward not in REWARDS:
            raise ValueError(f"reward must be one of {REWARDS}, got {self.reward!r}")
        set_("cost_scale", as_float(self.cost_scale, "cost_scale (an error norm)", positive=True))
        if self.render_mode is not None and (not isinstance(self.render_mode, str) or self.render_mode not in RENDER_MODES):
            raise ValueError(f"render_mode must be None or one of {list(RENDER_MODES)}, got {self.render_mode!r}")
        if not isinstance(self.disturbance, str) or self.disturbance not in DISTURBANCES:
            raise ValueError(f"disturbance must be one of {DISTURBANCES}, got {self.disturbance!r}")
        set_("disturbance_amplitude", as_float(self.disturbance_amplitude, "disturbance_amplitude", minimum=0.0))
        for name in ("normalized_actions", "padded_observations"):
            set_(name, as_flag(getattr(self, name), name))
        set_("faults", Faults.from_value(self.faults))


@dataclass(frozen=True, eq=False)
class HeteroMASOptions(EnvOptions):
    """:class:`EnvOptions` plus the rendezvous task parameters of ``hetero_mas_v0``
    (:func:`~dobs_envs.scenarios.mas_tasks.rendezvous_scenario`)."""

    q_rest: float = 0.1
    r: float = 1.0
    rho: float = 1e-3

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "q_rest", as_float(self.q_rest, "q_rest", minimum=0.0))
        object.__setattr__(self, "r", as_float(self.r, "r", positive=True))
        object.__setattr__(self, "rho", as_float(self.rho, "rho", minimum=0.0))


@dataclass(frozen=True, eq=False)
class RandomNetworkOptions(EnvOptions):
    """:class:`EnvOptions` plus the generator options of ``random_network_v0``
    (:mod:`dobs_envs.scenarios.random`); ``scenario`` is not accepted by that environment."""

    kind: str = "plant"
    system_seed: int = 0
    n_states: int = 6
    n_controllers: int = 3
    n_observers: int = 4
    n_agents: int = 4
    graph: str = "random"
    edge_prob: float = 0.3
    unknown_input: bool = False
    controller: str | None = None
    generator_kwargs: dict | None = None

    def __post_init__(self):
        super().__post_init__()
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        if not isinstance(self.kind, str) or self.kind not in ("plant", "mas"):
            raise ValueError(f"kind must be 'plant' or 'mas', got {self.kind!r}")
        if self.system_seed is None:
            raise ValueError("system_seed must be a non-negative integer (the system is reproducible), got None")
        set_("system_seed", check_seed(self.system_seed, "system_seed"))
        for name in ("n_states", "n_controllers", "n_observers", "n_agents"):
            set_(name, as_int(getattr(self, name), name, minimum=1, maximum=MAX_SIZE))
        if isinstance(self.graph, str) and self.graph not in GRAPH_TOPOLOGIES:
            raise ValueError(f"graph must be one of {GRAPH_TOPOLOGIES} (or a Graph / adjacency matrix), got {self.graph!r}")
        if not isinstance(self.graph, str) and isinstance(self.graph, (bool, int, float, complex, np.number)):
            raise ValueError(f"graph must be one of {GRAPH_TOPOLOGIES} (or a Graph / adjacency matrix), got {self.graph!r}")
        set_("edge_prob", as_float(self.edge_prob, "edge_prob (a probability)", minimum=0.0, maximum=1.0))
        set_("unknown_input", as_flag(self.unknown_input, "unknown_input"))
        if self.controller is not None and not isinstance(self.controller, str):
            raise ValueError(f"controller must be None or a controller name, got {self.controller!r}")
        if self.generator_kwargs is not None and not isinstance(self.generator_kwargs, dict):
            raise ValueError(f"generator_kwargs must be None or a dict, got {type(self.generator_kwargs).__name__}")
