"""dobs-envs: distributed-observer control benchmark (Cao & Yin).

Importing the package registers the Gymnasium ids ``dobs_envs/Tracking-v0``,
``dobs_envs/DisturbanceRejection-v0``, ``dobs_envs/HeteroMAS-v0`` and
``dobs_envs/RandomNetwork-v0`` (centralised single-agent views of the
PettingZoo environments ``dobs_envs.tracking_v0`` ...; see
:mod:`dobs_envs.envs.centralized`).
"""
__version__ = "0.1.0"

#: Gymnasium id -> (entry point, max_episode_steps); entry points are imported lazily by gym.make.
GYM_IDS = {
    "dobs_envs/Tracking-v0": ("dobs_envs.envs.centralized:make_tracking", 400),
    "dobs_envs/DisturbanceRejection-v0": ("dobs_envs.envs.centralized:make_disturbance_rejection", 400),
    "dobs_envs/HeteroMAS-v0": ("dobs_envs.envs.centralized:make_hetero_mas", 600),
    "dobs_envs/RandomNetwork-v0": ("dobs_envs.envs.centralized:make_random_network", 400),
}


def _register_gym_envs() -> None:
    try:
        from gymnasium.envs.registration import register, registry
    except ImportError:  # pragma: no cover - gymnasium is a dependency
        return
    for env_id, (entry_point, steps) in GYM_IDS.items():
        if env_id not in registry:
            register(id=env_id, entry_point=entry_point, max_episode_steps=steps)


_register_gym_envs()
