"""The search space of a study: :class:`SearchSpace`, Optuna's define-by-run space of one algorithm around a
recipe (learning rate and its schedule, rollout / batch sizes, gamma, the policy's initial log-std or gSDE, the
network size, the recipe's training-only state bound, ``train_freq`` / ``gradient_steps`` off-policy), its
sampled values as hyperparameter overrides, and the recipe itself as a point of the space (trial 0)."""
from __future__ import annotations

from typing import Any

from ..config.hyperparam_files import ALGOS

__all__ = ["SearchSpace", "NETS"]


#: the named network sizes of the search space (Optuna's categorical values must be scalars)
NETS = {"64x64": [64, 64], "128x128": [128, 128], "256x256": [256, 256], "400x300": [400, 300]}


def _net_name(net_arch) -> str | None:
    for name, arch in NETS.items():
        if list(net_arch or []) == arch:
            return name
    return None


class SearchSpace:
    """Optuna define-by-run search space of one algorithm around a recipe (``hp``: the merged
    hyperparameters in :mod:`agents.config.hyperparam_files`'s vocabulary) for a budget of ``timesteps`` env steps.

    ``space(trial)`` samples the parameters (Ray's ``OptunaSearch(space=...)``);
    :meth:`overrides` turns the sampled values into hyperparameter overrides (merged over the recipe
    by :func:`agents.training.recipes.resolve_recipe`); :meth:`baseline` is the recipe itself as a point of
    the space (None when one of its values lies outside).

    Sizes that cannot work with the budget are left out: PPO rollouts ``n_steps * n_envs`` of at most a
    quarter of the budget, minibatches no larger than a rollout (clipped), off-policy
    ``gradient_steps`` at most the samples collected per update (``train_freq * n_envs``) and
    ``learning_starts`` at most a quarter of the budget.
    """

    GAMMAS = (0.95, 0.98, 0.99, 0.995, 0.999)

    def __init__(self, algo: str, hp: dict, timesteps: int):
        if algo not in ALGOS:
            raise ValueError(f"algo must be one of {ALGOS}, got {algo!r}")
        self.algo, self.hp, self.timesteps = algo, dict(hp), int(timesteps)
        self.n_envs = int(hp.get("n_envs", 1))
        bound = (hp.get("env_kwargs") or {}).get("state_bound")
        self.state_bounds = tuple(float(f * bound) for f in (0.5, 1, 2, 4)) if bound else ()
        rollouts = [c for c in (64, 128, 256, 512, 1024, 2048) if c * self.n_envs <= self.timesteps // 4]
        self.n_steps = tuple(rollouts or [64])
        starts = [c for c in (100, 1000, 5000, 10000) if c <= self.timesteps // 4]
        self.learning_starts = tuple(starts or [0])

    # the parameters: (name, kind, choices or (low, high)); categorical choices are scalars
    def params(self) -> list[tuple[str, str, Any]]:
        common = [("learning_rate", "log", (1e-5, 3e-3)), ("lr_schedule", "cat", ("constant", "linear")),
                  ("gamma", "cat", self.GAMMAS)]
        if self.algo == "ppo":
            p = common + [("n_steps", "cat", self.n_steps), ("batch_size", "cat", (64, 128, 256, 512)),
                          ("n_epochs", "cat", (5, 10, 20)), ("gae_lambda", "cat", (0.9, 0.95, 0.98)),
                          ("clip_range", "cat", (0.1, 0.2, 0.3)), ("log_std_init", "float", (-4.0, -1.0)),
                          ("use_sde", "cat", (False, True)), ("net_arch", "cat", ("64x64", "128x128", "256x256"))]
        else:
            p = common + [("batch_size", "cat", (64, 128, 256, 512)), ("tau", "cat", (0.005, 0.01, 0.02, 0.05)),
                          ("train_freq", "cat", (1, 4, 8, 16)), ("gradient_steps", "cat", (1, 2, 4, 8, 16)),
                          ("learning_starts", "cat", self.learning_starts),
                          ("net_arch", "cat", ("64x64", "256x256", "400x300"))]
            if self.algo == "sac":
                p += [("log_std_init", "float", (-4.0, 0.0)), ("use_sde", "cat", (False, True))]
            else:
                p += [("noise_std", "cat", (0.02, 0.05, 0.1, 0.2, 0.3))]
        if self.state_bounds:
            p.append(("state_bound", "cat", self.state_bounds))
        return p

    def __call__(self, trial) -> None:
        for name, kind, arg in self.params():
            if kind == "cat":
                trial.suggest_categorical(name, list(arg))
            else:
                trial.suggest_float(name, *arg, log=kind == "log")

    def overrides(self, params: dict) -> dict:
        """Hyperparameter overrides of the sampled ``params`` (agents' vocabulary; ``policy_kwargs`` and
        ``env_kwargs`` are merged into the recipe's, keeping e.g. its activation)."""
        p = dict(params)
        unknown = set(p) - {name for name, _, _ in self.params()}
        if unknown:
            raise ValueError(f"parameters {sorted(unknown)} are not in the {self.algo} search space")
        out: dict = {}
        lr = float(p.pop("learning_rate"))
        out["learning_rate"] = f"lin_{lr:.6g}" if p.pop("lr_schedule") == "linear" else lr
        pk = {"net_arch": list(NETS[p.pop("net_arch")])}
        if "log_std_init" in p:
            pk["log_std_init"] = float(p.pop("log_std_init"))
        out["policy_kwargs"] = pk
        if "state_bound" in p:
            out["env_kwargs"] = {"state_bound": float(p.pop("state_bound"))}
        if self.algo == "ppo":
            p["batch_size"] = min(int(p["batch_size"]), int(p["n_steps"]) * self.n_envs)
        else:
            p["gradient_steps"] = min(int(p["gradient_steps"]), int(p["train_freq"]) * self.n_envs)
        out.update(p)
        return out

    def baseline(self) -> dict | None:
        """The recipe's own values as a point of the space (None if one lies outside it)."""
        hp, pk = self.hp, dict(self.hp.get("policy_kwargs") or {})
        lr = hp.get("learning_rate", 3e-4)
        sched = "constant"
        if isinstance(lr, str) and lr.startswith("lin_"):
            lr, sched = lr[4:], "linear"
        defaults = {"ppo": {"log_std_init": 0.0, "net_arch": [64, 64]},
                    "sac": {"log_std_init": -3.0, "net_arch": [256, 256]}, "td3": {"net_arch": [400, 300]}}[self.algo]
        values = {"learning_rate": float(lr), "lr_schedule": sched,
                  "net_arch": _net_name(pk.get("net_arch", defaults["net_arch"])),
                  "log_std_init": float(pk.get("log_std_init", defaults.get("log_std_init", 0.0))),
                  "use_sde": bool(hp.get("use_sde", False)),
                  "state_bound": float((hp.get("env_kwargs") or {}).get("state_bound", 0.0))}
        point = {}
        for name, kind, arg in self.params():
            v = values.get(name, hp.get(name))
            if kind == "cat":
                if v not in arg:
                    return None
            elif v is None or not arg[0] <= float(v) <= arg[1]:
                return None
            point[name] = v
        return point
