"""The XLA CPU runtime as the jitted trainers set it up (:mod:`agents.training.xla`).

Each test runs a fresh Python process: the flags and the thread pool are fixed when JAX creates its CPU client,
once per process, so they cannot be tested inside the pytest process (whose JAX may already run).
"""
import importlib.util
import os
import subprocess
import sys
import textwrap

import pytest

pytestmark = [
    pytest.mark.skipif(importlib.util.find_spec("jax") is None, reason="the jax extra is not installed"),
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="counts XLA threads by their names in /proc"),
]

FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler"

#: the smallest jitted PPO that deadlocked (tracking, 2 copies x 16 steps, 2 updates): built and vmapped over
#: ``N`` seeds
TINY_PPO = """
    import jax, jax.numpy as jnp
    from agents.training.jax.ppo import HPARAMS, make_env, make_train, ppo_config
    from agents.training.recipes import resolve_recipe
    hp = dict(resolve_recipe("ppo", "tracking", trainer="jax").hyperparams)
    hp.update({"n_envs": 2, "n_steps": 16, "batch_size": 32, "n_epochs": 1})
    cfg, hp0 = ppo_config(hp, "dobs_envs/Tracking-v0", total_timesteps=64, dtype="float32")
    env, env_params = make_env(cfg)
    train = make_train(cfg, env, env_params)
"""


def _run(code: str, env_extra: dict, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "PJRT_NPROC")}
    env.update(env_extra)
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True, text=True,
                         timeout=timeout)
    assert out.returncode == 0, out.stderr[-3000:]
    return out


def test_vmapped_ppo_finishes_with_two_xla_threads():
    """With a 2-thread CPU client (PJRT_NPROC=2) the vmapped jitted PPO over 2 seeds finishes and is finite.
    Without the flag that importing agents.training.jax adds, this program deadlocked in every one of the
    fresh processes tried on the 2-core machine (jaxlib 0.10.2; the module doc of agents.training.xla): the
    process then never returns and the timeout fails the test. The same program takes ~15 s."""
    code = TINY_PPO + """
    import os
    from agents.training.xla import xla_pool_threads
    n = 2
    hps = {k: jnp.full((n,), hp0[k], jnp.float32) for k in HPARAMS}
    keys = jnp.stack([jax.random.PRNGKey(s) for s in range(n)])
    out = jax.block_until_ready(jax.jit(jax.vmap(train))(keys, hps))
    finite = all(bool(jnp.isfinite(v).all()) for v in jax.tree.leaves(out["params"]))
    print(xla_pool_threads(), finite, os.environ["XLA_FLAGS"])
    """
    out = _run(code, {"PJRT_NPROC": "2"}, timeout=480)
    threads, finite, flags = out.stdout.split()
    assert int(threads) == 2  # the multi-threaded client the deadlock needs
    assert finite == "True"
    assert flags == f"{FLAG}=false"


def test_user_setting_of_the_flag_is_kept():
    """A value of the flag the user set is not replaced; other user flags stay."""
    code = """
    import os
    import agents.training.jax
    print(os.environ["XLA_FLAGS"])
    """
    user = f"--xla_cpu_enable_fast_math=false {FLAG}=true"
    assert _run(code, {"XLA_FLAGS": user}).stdout.strip() == user
    assert _run(code, {"XLA_FLAGS": "--xla_cpu_enable_fast_math=false"}).stdout.strip() == \
        f"--xla_cpu_enable_fast_math=false {FLAG}=false"


@pytest.mark.parametrize("nproc, warns", [("2", True), ("1", False)])
def test_warning_when_jax_already_runs_several_threads(nproc, warns):
    """JAX started (a computation) before agents.training.jax was imported, so the flag cannot take effect: building
    a trainer warns, naming the thread count and the remedies, iff the client has more than one thread."""
    code = """
    import warnings
    import jax.numpy as jnp
    float((jnp.ones((64, 64)) @ jnp.ones((64, 64))).sum())  # JAX's CPU client now exists
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
    """ + textwrap.indent(textwrap.dedent(TINY_PPO), "        ") + """
    from agents.training.jax.sac import make_train as sac_make_train, sac_config
    hp = dict(resolve_recipe("sac", "tracking", trainer="jax").hyperparams)
    with warnings.catch_warnings(record=True) as caught_sac:
        warnings.simplefilter("always")
        sac_make_train(sac_config(hp, "dobs_envs/Tracking-v0", total_timesteps=64)[0])
    for w in caught + caught_sac:
        if issubclass(w.category, RuntimeWarning):
            print("WARNING", w.message)
    """
    out = _run(code, {"PJRT_NPROC": nproc}).stdout
    lines = [line for line in out.splitlines() if line.startswith("WARNING")]
    if not warns:
        assert lines == []
        return
    assert len(lines) == 2, out
    assert "agents.training.jax.ppo.make_train: JAX's CPU client runs 2 XLA threads" in lines[0]
    assert "agents.training.jax.sac.make_train" in lines[1]
    assert f"{FLAG}=false" in lines[0] and "PJRT_NPROC=1" in lines[0]
