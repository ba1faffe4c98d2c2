"""The fields of a jitted run's ``config.json`` as the run directories have recorded them since the jitted trainer's
SAC / TD3 runs (copied from such runs, not from the code that writes them): the tests of the three writers
(agents.training.jax.run.train_jax, run_marl.train_jax_marl, vmap_seeds.train_jax_seeds) check a finished run's keys
against them, so a field cannot drift between the writers or vanish unnoticed."""

#: a centralised run's (PPO, SAC, TD3)
CONFIG_KEYS = frozenset([
    "env", "algo", "trainer", "library", "library_version", "jax_version", "jaxlib_version", "optax_version", "env_id",
    "dtype", "multi_agent", "hybrid", "seed", "key", "timesteps", "timesteps_done", "n_updates", "rollout", "n_agents",
    "normalize_actions", "env_kwargs", "train_env_kwargs", "normalize", "hyperparams", "policy", "curve_seeds",
    "status", "setup_seconds", "compile_seconds", "compile_cpu_seconds", "train_seconds", "train_cpu_seconds",
    "curve_seconds", "total_seconds", "total_cpu_seconds",
    # since 2026-12-06 (agents.training.provenance): the runs of results/ trained before lack it
    "provenance"])
#: a shared-policy run's (train --trainer jax --multi-agent)
MARL_CONFIG_KEYS = CONFIG_KEYS | {"marl_env", "samples_per_update", "agent_id"}
#: a seed of a vmapped run adds the shared figures
VMAPPED_KEY = "vmapped"
