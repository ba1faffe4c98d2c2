"""The JAX libraries the JAX environments (dobs_envs.jax) are written for, for real: gymnax's wrappers on
the centralised view, JaxMARL's LogWrapper with the batching of its IPPO scripts on the multi-agent view,
and a short rejax PPO training. They live here because gymnax 1.0 (and so JaxMARL and rejax) needs
gymnasium < 1.4 while the main suite runs on the newest gymnasium; this environment has ray's 1.2.2."""
import jax
import jax.numpy as jnp
import numpy as np
import rejax
from gymnax.wrappers.purerl import LogWrapper
from jaxmarl.wrappers.baselines import LogWrapper as MarlLogWrapper

from dobs_envs.jax import make, make_marl
from dobs_envs.jax.wrappers import DoneStepWrapper


def test_gymnax_log_wrapper_records_the_episode_returns():
    env, params = make("dobs_envs/Tracking-v0", max_episode_steps=5)
    wrapped = LogWrapper(env)
    B, T = 3, 12
    _, state = jax.vmap(wrapped.reset, in_axes=(0, None))(jax.random.split(jax.random.PRNGKey(0), B), params)

    def body(s, k):
        obs, s, r, term, trunc, info = jax.vmap(wrapped.step, in_axes=(0, 0, None, None))(
            jax.random.split(k, B), s, jnp.zeros(5), params)
        return s, (r, term | trunc, info["returned_episode_returns"])

    _, (r, done, ret) = jax.lax.scan(body, state, jax.random.split(jax.random.PRNGKey(1), T))
    done, r, ret = np.asarray(done), np.asarray(r), np.asarray(ret)
    np.testing.assert_array_equal(done[:, 0], [False] * 4 + [True] + [False] * 4 + [True] + [False] * 2)
    np.testing.assert_allclose(ret[4], r[:5].sum(axis=0), rtol=1e-5)  # the first episode's return
    np.testing.assert_allclose(ret[9], r[5:10].sum(axis=0), rtol=1e-5)


def test_jaxmarl_log_wrapper_with_the_ippo_batching():
    """What JaxMARL's IPPO scripts do with an environment: LogWrapper, vmapped reset/step over NUM_ENVS, the
    agents' observations stacked into NUM_ACTORS rows, the infos reshaped to NUM_ACTORS."""
    env = MarlLogWrapper(make_marl("tracking_v0", normalized_actions=True, max_episode_steps=4))
    num_envs = 4
    num_actors = env.num_agents * num_envs
    obs, state = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(0), num_envs))

    @jax.jit
    def step(state, key):
        ka, ks = jax.random.split(key)
        acts = {a: jax.vmap(env.action_space(a).sample)(jax.random.split(jax.random.fold_in(ka, i), num_envs))
                for i, a in enumerate(env.agents)}
        obs, state, reward, done, info = jax.vmap(env.step)(jax.random.split(ks, num_envs), state, acts)
        info = jax.tree.map(lambda x: x.reshape((num_actors,)), info)
        batch = jnp.stack([obs[a] for a in env.agents]).reshape((num_actors, -1))
        return state, (batch, reward, done, info)

    rewards = []
    for k in range(4):
        state, (batch, reward, done, info) = step(state, jax.random.PRNGKey(10 + k))
        rewards.append(np.asarray(reward["controller_0"]))
    assert batch.shape == (num_actors, env.observation_space("controller_0").shape[0])
    assert bool(np.all(np.asarray(done["__all__"])))  # the 4-step horizon
    team = np.sum(rewards, axis=0)  # (num_envs,)
    per_actor = np.asarray(info["returned_episode_returns"]).reshape(num_envs, env.num_agents)  # as vmapped
    np.testing.assert_allclose(per_actor, np.repeat(team[:, None], env.num_agents, axis=1), rtol=1e-5)


def test_rejax_ppo_trains_on_tracking():
    env, params = make("dobs_envs/Tracking-v0", normalized_actions=True)
    algo = rejax.PPO.create(env=DoneStepWrapper(env), env_params=params, total_timesteps=4096, num_envs=8,
                            num_steps=64, num_epochs=1, num_minibatches=2, eval_freq=4096,
                            normalize_observations=True)
    train_state, (lengths, returns) = jax.jit(algo.train)(jax.random.PRNGKey(0))
    returns = np.asarray(returns)
    assert returns.ndim == 2 and np.all(np.isfinite(returns)) and np.all(returns < 0)  # costs: negative returns
    assert int(train_state.global_step) >= 4096
