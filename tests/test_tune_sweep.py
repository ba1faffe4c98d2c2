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

    best = yaml.safe_load((tmp_path / "best.yml").read_text())
    (section, hp), = best.items()
    assert section == "dobs_envs/Tracking-v0" and hp["n_envs"] == 2 and hp["n_timesteps"] == 64
    cfg, hps = ppo_config(hp, section)
    for k, v in doc["best"]["floats"].items():
        assert hps[k] == pytest.approx(v, rel=1e-5), k
    with pytest.raises(SystemExit) as exc:  # the record is never overwritten without --overwrite
        main(["--env", "tracking", "--out", str(tmp_path), "--timesteps", "64"])
    assert exc.value.code == 2
