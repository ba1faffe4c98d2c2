"""dobs-envs: distributed-observer control benchmark (Cao & Yin).

Importing the package registers one Gymnasium id per entry of
:mod:`dobs_envs.registry` (``dobs_envs/Tracking-v0``,
``dobs_envs/DisturbanceRejection-v0``, ``dobs_envs/HeteroMAS-v0``,
``dobs_envs/RandomNetwork-v0``): centralised single-agent views of the
PettingZoo environments ``dobs_envs.tracking_v0`` ... (see
:mod:`dobs_envs.envs.centralized`), each with a ``vector_entry_point`` so that
``gym.make_vec(id, num_envs=B)`` builds the native batched vector env
(:mod:`dobs_envs.envs.vector`). Entry points are imported lazily by ``gym.make``.
"""
__version__ = "0.1.0"

from .registry import ENVIRONMENTS as _ENVIRONMENTS  # noqa: E402
from .registry import GYM_IDS  # noqa: E402  (Gymnasium id -> (entry point, max_episode_steps))


def _register_gym_envs() -> None:
    try:
        from gymnasium.envs.registration import register, registry
    except ImportError:  # pragma: no cover - gymnasium is a dependency
        return
    for e in _ENVIRONMENTS.values():
        if e.gym_id not in registry:
            register(id=e.gym_id, entry_point=e.gym_entry_point, max_episode_steps=e.max_episode_steps,
                     vector_entry_point=e.gym_vector_entry_point)


_register_gym_envs()
