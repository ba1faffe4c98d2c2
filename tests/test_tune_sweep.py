"""The vmapped sweep of the jitted PPO (agents.tune.sweep, issue 40 item 4): its float points, its record
and its recipe file, with the real jitted trainer and the benchmark's harness."""
from __future__ import annotations

import json
import math

import pytest
import yaml

pytest.importorskip("jax")

from agents.training.seeds import TUNING  # noqa: E402
from agents.tune.sweep import FLOAT_SPACE, main, run_sweep, sample_floats  # noqa: E402


def test_point_zero_is_the_recipe_and_the_others_lie_in_the_space():
    recipe = {k: (lo + hi) / 2 for k, (_, lo, hi) in FLOAT_SPACE.items()}
    pts = sample_floats(recipe, 33, seed=1)
    assert pts[0] == recipe and len(pts) == 33
    for k, (kind, lo, hi) in FLOAT_SPACE.items():
        vals = [p[k] for p in pts[1:]]
        assert all(lo <= v <= hi for v in vals), k
        # spread over the range (Sobol): both halves (log halves for log-uniform ones) are visited
        mid = math.sqrt(lo * hi) if kind == "log" else (lo + hi) / 2
        assert min(vals) < mid < max(vals), k
    assert sample_floats(recipe, 5, seed=1) == pts[:5]  # the sequence's prefix: reproducible per seed


def test_a_tiny_sweep_writes_its_record_and_a_recipe_that_trains(tmp_path):
    """Two float points x one seed of a tiny structure: every run scored on tuning episodes (J/J_paper > 0,
    finite or inf for a diverged run), the winner the lowest score, best.yml a recipe section that the
    jitted trainer's config reads back with the winner's floats."""
    structure = {"n_envs": 2, "n_steps": 16, "batch_size": 32, "n_epochs": 1}
    rec = run_sweep("tracking", timesteps=64, structures=[structure], draws=2, seeds=[0], episodes=1,
                    out=str(tmp_path), log=lambda *_: None)
    doc = json.loads((tmp_path / "sweep.json").read_text())
    assert doc["status"] == "complete" and doc["episode_seeds"] == [TUNING.start]
    assert [t["trial"] for t in doc["trials"]] == [0, 1] and doc["trials"][0]["recipe_floats"]
    assert all(t["score"] > 0 for t in rec["trials"])
    assert doc["best"]["score"] == min(t["score"] for t in doc["trials"])
    from agents.training.jax.ppo import ppo_config

    text = (tmp_path / "best.yml").read_text()
    # its comments say how to use it: a --recipe file of the centralised agent (the shared policy's is the next test's)
    assert "--recipe FILE" in text and "section tracking-jax of" in text and "--multi-agent" not in text
    best = yaml.safe_load(text)
    (section, raw), = best.items()
    assert section == "dobs_envs/Tracking-v0" and raw["n_envs"] == 2 and raw["n_timesteps"] == 64
    from agents.training.recipes import recipe_file_section
    from agents.tune.compare import candidate_recipe

    # a recipe file in rl-zoo3's vocabulary, as `train --recipe` and `agents.tune.compare` read it
    hp = recipe_file_section(str(tmp_path / "best.yml"), "tracking")
    cfg, hps = ppo_config(hp, section)
    for k, v in doc["best"]["floats"].items():
        assert hps[k] == pytest.approx(v, rel=1e-5), k
    assert ppo_config(candidate_recipe(str(tmp_path / "best.yml"), "tracking"), section)[1] == hps
    with pytest.raises(SystemExit) as exc:  # the record is never overwritten without --overwrite
        main(["--env", "tracking", "--out", str(tmp_path), "--timesteps", "64"])
    assert exc.value.code == 2


def test_a_tiny_shared_policy_sweep_scores_through_the_pettingzoo_env(tmp_path):
    """--multi-agent: the shared-policy PPO's recipe (agent_id from the -ma sections), its runs scored on the
    PettingZoo env; best.yml is the ppo.yaml section tracking-ma-jax, which ippo_config reads back with the
    winner's floats."""
    from agents.training.jax.ippo import ippo_config
    from agents.training.recipes import resolve_recipe

    structure = {"n_envs": 2, "n_steps": 16, "batch_size": 32, "n_epochs": 1}
    rec = run_sweep("tracking", timesteps=64, structures=[structure], draws=2, seeds=[0], episodes=1,
                    out=str(tmp_path), multi_agent=True, log=lambda *_: None)
    assert rec["multi_agent"] and rec["recipe"] == dict(resolve_recipe("ppo", "tracking", multi_agent=True,
                                                                       trainer="jax").hyperparams)
    assert all(t["score"] > 0 for t in rec["trials"])
    text = (tmp_path / "best.yml").read_text()
    assert "shared-policy PPO" in text and "section tracking-ma-jax of" in text and "--multi-agent" in text
    (section, hp), = yaml.safe_load(text).items()
    assert section == "tracking-ma-jax" and hp["n_envs"] == 2 and hp["agent_id"] == rec["recipe"]["agent_id"]
    _, hps = ippo_config(hp, "tracking", total_timesteps=64)
    for k, v in rec["best"]["floats"].items():
        assert hps[k] == pytest.approx(v, rel=1e-5), k
    # the file as `agents.tune.compare --multi-agent` and `train --trainer jax --multi-agent --recipe` read it: its
    # tracking-ma-jax section, not the centralised agent's (which the file lacks)
    from agents.config.hyperparam_files import HyperparamsError
    from agents.training.recipes import recipe_file_section
    from agents.tune.compare import candidate_recipe

    path = str(tmp_path / "best.yml")
    assert recipe_file_section(path, "tracking", multi_agent=True, trainer="jax") == hp
    assert ippo_config(candidate_recipe(path, "tracking", multi_agent=True), "tracking", total_timesteps=64)[1] == hps
    with pytest.raises(HyperparamsError, match="no section 'tracking-jax' or 'dobs_envs/Tracking-v0' or 'default'"):
        recipe_file_section(path, "tracking", trainer="jax")
