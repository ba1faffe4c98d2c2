"""Run as a script (by tests/clients/test_rl_zoo3.py): what rl-zoo3's ExperimentManager makes of
agents/config/hyperparams/<algo>.yaml for every dobs_envs Gymnasium id, as JSON on stdout.

A separate process because ``import rl_zoo3`` patches Gymnasium's ``TimeLimit`` for the whole
process (rl_zoo3/gym_patches.py adds a ``TimeLimit.truncated`` info key), which would leak into
every other test of the suite."""
from __future__ import annotations

import argparse
import json
import sys
import tempfile


def reading(algo: str, gym_id: str, config: str, log_folder: str) -> dict:
    import gymnasium as gym
    from rl_zoo3.exp_manager import ExperimentManager

    em = ExperimentManager(argparse.Namespace(), algo, gym_id, log_folder, config=config)
    hp, _ = em.read_hyperparameters()
    hp, env_wrapper, callbacks, vec_env_wrapper = em._preprocess_hyperparams(hp)
    wrapped = env_wrapper(gym.make(gym_id)) if env_wrapper is not None else None
    out = {"n_envs": em.n_envs, "n_timesteps": em.n_timesteps, "env_kwargs": em.env_kwargs,
           "eval_env_kwargs": em.eval_env_kwargs, "normalize": em.normalize_kwargs if em.normalize else False,
           "callbacks": len(callbacks), "vec_env_wrapper": vec_env_wrapper is not None,
           "action_low": None if wrapped is None else wrapped.action_space.low.tolist(),
           "action_high": None if wrapped is None else wrapped.action_space.high.tolist(),
           "env_action_low": None if wrapped is None else wrapped.unwrapped.action_space.low.tolist(),
           "kwargs": {}}
    for key, value in hp.items():
        if key == "policy_kwargs":
            value = {k: (v.__name__ if isinstance(v, type) else v) for k, v in value.items()}
        elif callable(value):  # rl-zoo3's schedules
            value = {"schedule": [value(p) for p in (1.0, 0.5, 0.1)]}
        out["kwargs"][key] = value
    return out


def main() -> None:
    import dobs_envs  # noqa: F401  (registers the ids, as --gym-packages dobs_envs does)
    from agents.config.hyperparam_files import ALGOS, HYPERPARAMS_DIR
    from agents.config.envs import ENVS

    result = {}
    with tempfile.TemporaryDirectory() as tmp:
        for algo in ALGOS:
            for gym_id, _ in ENVS.values():
                result[f"{algo} {gym_id}"] = reading(algo, gym_id, f"{HYPERPARAMS_DIR}/{algo}.yaml", tmp)
    json.dump(result, sys.stdout)


if __name__ == "__main__":
    main()
