"""dobs-envs: distributed-observer control benchmark (Cao & Yin).

Importing the package registers one Gymnasium id per entry of
:mod:`dobs_envs.registry` (``dobs_envs/Tracking-v0``,
``dobs_envs/DisturbanceRejection-v0``, ``dobs_envs/HeteroMAS-v0``,
``dobs_envs/RandomNetwork-v0``): centralised single-agent views of the
PettingZoo environments ``dobs_envs.tracking_v0`` ... (see
:mod:`dobs_envs.envs.centralized`). Entry points are imported lazily by ``gym.make``.
"""
__version__ = "0.1.0"

from .registry import GYM_IDS  # noqa: E402  (Gymnasium id -> (entry point, max_episode_steps))


def _register_gym_envs() -> None:
    try:
        from gymnasium.envs.registration import register, registry
    except ImportError:  # pragma: no cover - gymnasium is a dependency
        return
    for env_id, (entry_point, steps) in GYM_IDS.items():
        if env_id not in registry:
            register(id=env_id, entry_point=entry_point, max_episode_steps=steps)


_register_gym_envs()
