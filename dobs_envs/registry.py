"""The environment registry: one record per named environment of the suite.

Read by the Gymnasium registration (:mod:`dobs_envs`), the PettingZoo modules
(``dobs_envs.tracking_v0`` ...), :mod:`dobs_envs.envs.centralized` and
``agents.config.envs.ENVS``. Importing it is cheap: plain data, no numpy and no
observer designs. ``max_episode_steps`` is derived from the default scenario's
horizon ``t_end`` and the default control period ``DEFAULT_DT * DEFAULT_SUBSTEPS``
(tests check both against the environments' actual defaults).
The table of ids and episode lengths is in :mod:`dobs_envs.envs.centralized`.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass

__all__ = ["DEFAULT_DT", "DEFAULT_SUBSTEPS", "DEFAULT_CONTROL_PERIOD", "EnvEntry", "ENVIRONMENTS", "GYM_IDS",
           "get"]

#: Default Euler step (s) and Euler steps per control step of every environment
#: (the ``dt``/``substeps`` defaults of :class:`dobs_envs.envs.options.EnvOptions`).
DEFAULT_DT = 1e-3
DEFAULT_SUBSTEPS = 50
#: Default control period (s): 0.05.
DEFAULT_CONTROL_PERIOD = DEFAULT_DT * DEFAULT_SUBSTEPS


@dataclass(frozen=True)
class EnvEntry:
    """One named environment.

    Attributes
    ----------
    name : short name (``"tracking"``), the key of :data:`ENVIRONMENTS`.
    module : PettingZoo-convention module (``parallel_env``, ``raw_env``, ``env``).
    entry_point : ``"package.module:Class"`` of the ParallelEnv class.
    gym_id : registered id of the centralised Gymnasium view.
    t_end : horizon (s) of the default scenario (e.g. NE2's 20 s).
    default_scenario : what the environment simulates by default (documentation).
    fault_free : for an environment with communication faults on by default, the short name of its
        fault-free counterpart: the same task with ``faults=None`` (``"tracking"`` for
        ``"tracking_lossy"``; tested); None for the fault-free tasks.
    """

    name: str
    module: str
    entry_point: str
    gym_id: str
    t_end: float
    default_scenario: str
    fault_free: str | None = None

    @property
    def max_episode_steps(self) -> int:
        """``t_end`` in default control periods (rounded as the environments round ``horizon``)."""
        return max(1, int(round(self.t_end / DEFAULT_CONTROL_PERIOD)))

    @property
    def gym_entry_point(self) -> str:
        """The Gymnasium entry point: ``dobs_envs.envs.centralized:make_<name>``."""
        return f"dobs_envs.envs.centralized:make_{self.name}"

    @property
    def gym_vector_entry_point(self) -> str:
        """The Gymnasium ``vector_entry_point``: ``dobs_envs.envs.vector:make_vec_<name>``."""
        return f"dobs_envs.envs.vector:make_vec_{self.name}"

    def load_class(self) -> type:
        """Import and return the ParallelEnv class named by :attr:`entry_point`."""
        mod, cls = self.entry_point.split(":")
        return getattr(importlib.import_module(mod), cls)


def _entries(*entries: EnvEntry) -> dict:
    return {e.name: e for e in entries}


#: short name -> :class:`EnvEntry`
ENVIRONMENTS = _entries(
    EnvEntry("tracking", "dobs_envs.tracking_v0", "dobs_envs.envs.tracking:TrackingEnv",
             "dobs_envs/Tracking-v0", 20.0, "NE2 (dobs_envs.scenarios.paper.ne2)"),
    EnvEntry("tracking_lossy", "dobs_envs.tracking_lossy_v0", "dobs_envs.envs.tracking:TrackingLossyEnv",
             "dobs_envs/TrackingLossy-v0", 20.0,
             "NE2 with communication faults and sensor noise (dobs_envs.envs.tracking.TRACKING_LOSSY_FAULTS)",
             fault_free="tracking"),
    EnvEntry("disturbance_rejection", "dobs_envs.disturbance_rejection_v0",
             "dobs_envs.envs.disturbance:DisturbanceRejectionEnv",
             "dobs_envs/DisturbanceRejection-v0", 20.0, "NE3 (dobs_envs.scenarios.paper.ne3)"),
    EnvEntry("hetero_mas", "dobs_envs.hetero_mas_v0", "dobs_envs.envs.hetero_mas:HeteroMASEnv",
             "dobs_envs/HeteroMAS-v0", 30.0, "NE1 rendezvous (dobs_envs.scenarios.mas_tasks.rendezvous_scenario)"),
    EnvEntry("random_network", "dobs_envs.random_network_v0", "dobs_envs.envs.random_network:RandomNetworkEnv",
             "dobs_envs/RandomNetwork-v0", 20.0,
             "seeded random plant (dobs_envs.scenarios.random.random_plant_scenario; Scenario.t_end default)"),
)

#: Gymnasium id -> (entry point, max_episode_steps), as registered by :mod:`dobs_envs`
#: (each id also has the vector entry point :attr:`EnvEntry.gym_vector_entry_point`).
GYM_IDS = {e.gym_id: (e.gym_entry_point, e.max_episode_steps) for e in ENVIRONMENTS.values()}


def get(name: str) -> EnvEntry:
    """The entry of ``name``; ``KeyError`` lists the registered names."""
    try:
        return ENVIRONMENTS[name]
    except KeyError:
        raise KeyError(f"no environment named {name!r}; registered names are {sorted(ENVIRONMENTS)}") from None
