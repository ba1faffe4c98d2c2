"""Choosing between jitted PPO, SAC and TD3 recipes on the tuning range (agents.tune.compare): candidates' recipes, the record
and its statistics, with the real jitted trainer and the benchmark's harness."""
from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

pytest.importorskip("jax")

from agents.training.recipes import resolve_recipe  # noqa: E402
from agents.training.seeds import TUNING  # noqa: E402
from agents.tune import sweep  # noqa: E402
from agents.tune.compare import _as_json, _p_better, candidate_recipe, compare_recipes, main  # noqa: E402

TINY = {"n_envs": 2, "n_steps": 16, "batch_size": 32, "n_epochs": 1}


def _recipe_file(path, **keys):
    """A complete recipe section (rl-zoo3 reads a section alone) with a tiny structure; the keys it does not set
    come from the jitted recipe when a comparison reads it."""
    section = {"policy": "MlpPolicy", "n_timesteps": 64, **TINY, "learning_rate": 3e-4,
               "policy_kwargs": "dict(net_arch=[64, 64], activation_fn=nn.Tanh, log_std_init=-2.0)", **keys}
    path.write_text(yaml.safe_dump({"dobs_envs/Tracking-v0": section}))
    return str(path)


def test_candidates_are_the_shipped_recipes_or_a_file_over_the_jitted_one(tmp_path):
    assert candidate_recipe("sb3", "tracking") == dict(resolve_recipe("ppo", "tracking").hyperparams)
    jax_hp = candidate_recipe("jax", "tracking")
    assert jax_hp == dict(resolve_recipe("ppo", "tracking", trainer="jax").hyperparams)
    rn = "random_network"  # its -jax section applies to the jax candidate only
    assert candidate_recipe("jax", rn)["n_envs"] != candidate_recipe("sb3", rn)["n_envs"]
    for source in ("sb3", "jax"):  # --multi-agent: the shared policy's sections
        assert candidate_recipe(source, "tracking", multi_agent=True) == dict(
            resolve_recipe("ppo", "tracking", multi_agent=True, trainer=source).hyperparams)
    f = candidate_recipe(_recipe_file(tmp_path / "a.yml", learning_rate=5e-4), "tracking")
    assert f["learning_rate"] == 5e-4 and f["n_envs"] == 2 and f["gae_lambda"] == jax_hp["gae_lambda"]


def test_probability_of_improvement_counts_ties_half():
    x, y = np.array([1.0, 2.0]), np.array([2.0, 3.0])
    assert _p_better(x, y) == pytest.approx((1 + 1 + 0.5 + 1) / 4)
    assert _p_better(x, y) + _p_better(y, x) == pytest.approx(1.0)
    # a diverged run (score inf) loses to every finite one and ties with another diverged run
    d = np.array([np.inf, 1.0])
    assert _p_better(d, np.array([np.inf, 2.0])) == pytest.approx((0.5 + 0 + 1 + 1) / 4)


def test_a_tiny_comparison_writes_its_record(tmp_path):
    """Two tiny recipes x two fresh seeds x one tuning episode: per-seed scores (J/J_paper > 0), the winner the
    lowest mean, P(a < b) + P(b < a) = 1; the record is never overwritten without --overwrite."""
    a = _recipe_file(tmp_path / "a.yml", learning_rate=1e-3)
    b = _recipe_file(tmp_path / "b.yml", learning_rate=1e-4)
    out = tmp_path / "cmp"
    sweep._COMPILED.clear()  # this process's compiled structures (another test's may match a's)
    rec = compare_recipes("tracking", {"a": a, "b": b}, timesteps=64, seeds=[100, 101], episodes=1, out=str(out),
                          log=lambda *_: None)
    doc = json.loads((out / "compare.json").read_text())
    assert doc["status"] == "complete" and doc["episode_seeds"] == [TUNING.start] and doc["seeds"] == [100, 101]
    for name, lr in (("a", 1e-3), ("b", 1e-4)):
        c = doc["candidates"][name]
        assert c["recipe"]["learning_rate"] == lr and len(c["seed_scores"]) == 2
        assert all(s > 0 for s in c["seed_scores"]) and c["mean"] == pytest.approx(np.mean(c["seed_scores"]))
    assert doc["winner"] == min("ab", key=lambda n: doc["candidates"][n]["mean"]) == rec["winner"]
    assert doc["p_improvement"]["a < b"] + doc["p_improvement"]["b < a"] == pytest.approx(1.0)
    # a and b differ in a float hyperparameter only (traced): b runs a's compiled program
    assert "compile_reused" not in doc["candidates"]["a"] and doc["candidates"]["a"]["compile_cpu_seconds"] > 0
    assert doc["candidates"]["b"]["compile_reused"] is True and doc["candidates"]["b"]["compile_cpu_seconds"] == 0
    with pytest.raises(SystemExit) as exc:
        main(["--env", "tracking", "--candidate", f"a={a}", "--candidate", f"b={b}", "--out", str(out)])
    assert exc.value.code == 2

    # --resume: b is kept (not trained again), b2 (b's recipe under a new name) is trained, and gives b's scores:
    # what a resumed comparison keeps is what a new run gives; statistics over all three candidates
    res = compare_recipes("tracking", {"b": b, "b2": b}, timesteps=64, seeds=[100, 101], episodes=1, out=str(out),
                          resume=True, log=lambda *_: None)
    doc2 = json.loads((out / "compare.json").read_text())
    assert list(doc2["candidates"]) == ["a", "b", "b2"] and res["status"] == doc2["status"] == "complete"
    assert doc2["candidates"]["b"] == {**doc["candidates"]["b"], "resumed": True}
    assert doc2["candidates"]["a"] == doc["candidates"]["a"]
    assert "resumed" not in doc2["candidates"]["b2"]
    assert doc2["candidates"]["b2"]["seed_scores"] == doc["candidates"]["b"]["seed_scores"]
    assert len(doc2["p_improvement"]) == 6 and doc2["p_improvement"]["b < b2"] == 0.5
    # a resumed comparison must be the same one, and a name keeps its recipe
    with pytest.raises(ValueError, match="its seeds is"):
        compare_recipes("tracking", {"c": a}, timesteps=64, seeds=[100, 102], episodes=1, out=str(out), resume=True)
    with pytest.raises(ValueError, match="another recipe under that name"):
        compare_recipes("tracking", {"a": b}, timesteps=64, seeds=[100, 101], episodes=1, out=str(out), resume=True)
    with pytest.raises(FileNotFoundError, match="no comparison to go on with"):
        compare_recipes("tracking", {"a": a}, timesteps=64, seeds=[100, 101], episodes=1, out=str(tmp_path / "none"),
                        resume=True)
    assert json.loads((out / "compare.json").read_text()) == doc2


def test_a_comparison_in_parts_joins_into_the_record_one_process_gives(tmp_path):
    """--part trains one candidate per process (a record without statistics); --join takes the parts in: the same
    scores, statistics and winner as the two candidates trained in one call; the parts must be the same comparison,
    and a name keeps its recipe across them."""
    a = _recipe_file(tmp_path / "a.yml", learning_rate=1e-3)
    b = _recipe_file(tmp_path / "b.yml", learning_rate=1e-4)
    kw = dict(timesteps=64, seeds=[100, 101], episodes=1, log=lambda *_: None)
    sweep._COMPILED.clear()
    one = compare_recipes("tracking", {"a": a, "b": b}, out=str(tmp_path / "one"), **kw)
    for name, f in (("a", a), ("b", b)):
        rec = compare_recipes("tracking", {name: f}, out=str(tmp_path / name), part=True, **kw)
        assert rec["status"] == "part" and "p_improvement" not in rec and "winner" not in rec
        assert json.loads((tmp_path / name / "compare.json").read_text())["status"] == "part"
    joined = compare_recipes("tracking", {}, out=str(tmp_path / "joined"), join=[str(tmp_path / "a"),
                                                                                  str(tmp_path / "b")], **kw)
    doc = json.loads((tmp_path / "joined" / "compare.json").read_text())
    assert doc["status"] == "complete" and list(doc["candidates"]) == ["a", "b"]
    for name in "ab":
        assert doc["candidates"][name]["joined_from"] == str(tmp_path / name)
        assert doc["candidates"][name]["seed_scores"] == one["candidates"][name]["seed_scores"]
        assert doc["candidates"][name]["recipe"] == _as_json(one["candidates"][name]["recipe"])
    assert doc["p_improvement"] == one["p_improvement"] and doc["winner"] == one["winner"] == joined["winner"]
    # a part may also be joined by a process that trains another candidate itself (b2: b's recipe, new name)
    more = compare_recipes("tracking", {"b2": b}, out=str(tmp_path / "more"), join=[str(tmp_path / "a")], **kw)
    assert list(more["candidates"]) == ["a", "b2"]
    assert more["candidates"]["b2"]["seed_scores"] == one["candidates"]["b"]["seed_scores"]
    # the parts must be the same comparison; a name keeps its recipe; the output is never one of the parts
    compare_recipes("tracking", {"a": b}, out=str(tmp_path / "a_other"), part=True, **kw)
    with pytest.raises(ValueError, match="another recipe than the candidate of that name"):
        compare_recipes("tracking", {}, out=str(tmp_path / "x"), join=[str(tmp_path / "a"), str(tmp_path / "a_other")],
                        **kw)
    with pytest.raises(ValueError, match="another recipe under that name"):
        compare_recipes("tracking", {"a": b}, out=str(tmp_path / "x"), join=[str(tmp_path / "a")], **kw)
    with pytest.raises(ValueError, match="another comparison: its seeds is"):
        compare_recipes("tracking", {}, out=str(tmp_path / "x"), join=[str(tmp_path / "a"), str(tmp_path / "b")],
                        **{**kw, "seeds": [100, 102]})
    with pytest.raises(ValueError, match="that is --out"):
        compare_recipes("tracking", {}, out=str(tmp_path / "a"), join=[str(tmp_path / "a"), str(tmp_path / "b")],
                        resume=True, **kw)
    with pytest.raises(ValueError, match="at least two candidates"):  # one part alone compares nothing
        compare_recipes("tracking", {}, out=str(tmp_path / "x"), join=[str(tmp_path / "a")], **kw)
    assert not (tmp_path / "x").exists()


def test_off_policy_candidates_are_their_algorithms_recipes(tmp_path):
    """--algo sac: ``sb3`` is sac.yaml's recipe as SBX trains it, ``jax`` the same with the jitted trainer's section
    (tracking's minibatch of 128; none on disturbance_rejection), a file's section is merged over the jitted
    trainer's recipe; a shared policy is PPO's only."""
    sac = dict(resolve_recipe("sac", "tracking").hyperparams)
    assert candidate_recipe("sb3", "tracking", algo="sac") == sac
    assert candidate_recipe("jax", "tracking", algo="sac") == {**sac, "batch_size": 128}
    assert candidate_recipe("jax", "disturbance_rejection", algo="sac") == dict(
        resolve_recipe("sac", "disturbance_rejection").hyperparams)
    f = tmp_path / "g4.yml"
    f.write_text(yaml.safe_dump({"dobs_envs/Tracking-v0": {"n_timesteps": 600000, "gradient_steps": 4}}))
    hp = candidate_recipe(str(f), "tracking", algo="sac")
    assert hp["gradient_steps"] == 4 and hp["train_freq"] == sac["train_freq"] == 4 and hp["batch_size"] == 128
    with pytest.raises(ValueError, match="PPO only"):
        candidate_recipe("sb3", "tracking", multi_agent=True, algo="sac")


def test_a_tiny_sac_comparison_trains_vmapped_seeds_and_scores_them(tmp_path):
    """Two tiny SAC recipes (learning rates apart) x two seeds x one tuning episode through the real jitted SAC:
    scores J/J_paper > 0 per seed, the two seeds' runs differ (vmapped keys), the record names the algorithm."""
    tiny = {"n_envs": 2, "train_freq": 4, "gradient_steps": 1, "batch_size": 16, "buffer_size": 256,
            "learning_starts": 16}
    files = {}
    for name, lr in (("a", 1e-3), ("b", 1e-4)):
        f = tmp_path / f"{name}.yml"
        f.write_text(yaml.safe_dump({"dobs_envs/Tracking-v0": {"n_timesteps": 64, **tiny, "learning_rate": lr}}))
        files[name] = str(f)
    out = tmp_path / "cmp"
    sweep._COMPILED.clear()
    rec = compare_recipes("tracking", files, timesteps=64, seeds=[100, 101], episodes=1, out=str(out), algo="sac",
                          log=lambda *_: None)
    doc = json.loads((out / "compare.json").read_text())
    assert doc["algo"] == "sac" and doc["status"] == "complete" and rec["winner"] in "ab"
    for name, lr in (("a", 1e-3), ("b", 1e-4)):
        c = doc["candidates"][name]
        assert c["recipe"]["learning_rate"] == lr and c["recipe"]["gradient_steps"] == 1
        assert len(c["seed_scores"]) == 2 and all(x > 0 for x in c["seed_scores"])
        assert c["seed_scores"][0] != c["seed_scores"][1]
        assert c["cpu_seconds"] > 0
    assert doc["candidates"]["b"]["compile_reused"] is True  # a and b differ in a traced float only


@pytest.mark.parametrize("argv, message", [
    (["--candidate", "a=sb3"], "at least two candidates"),
    (["--part"], "give the candidate(s) this process trains"),
    (["--candidate", "a=sb3", "--part", "--join", "x"], "give one"),
    (["--join", "/no/such/dir"], "no comparison record in /no/such/dir"),
    (["--join", "x", "--join", "x"], "a directory given twice"),
    (["--candidate", "a", "--candidate", "b=jax"], "expected NAME=SOURCE"),
    (["--candidate", "a=sb3", "--candidate", "a=jax"], "given twice"),
    (["--candidate", "a=sb3", "--candidate", "b=/no/such.yml"], "does not exist"),
    (["--candidate", "a=sb3", "--candidate", "b=jax", "--first-seed", "10000"], "--first-seed"),
    (["--candidate", "a=sb3", "--candidate", "b=jax", "--algo", "sac", "--multi-agent"], "PPO only"),
    (["--candidate", "a=sb3", "--candidate", "b=jax", "--resume", "--overwrite"], "give one"),
    (["--candidate", "a=sb3", "--resume"], "no comparison to go on with"),
])
def test_usage_errors_exit_2_with_one_line(tmp_path, capsys, argv, message):
    with pytest.raises(SystemExit) as exc:
        main(["--env", "tracking", "--out", str(tmp_path / "o"), *argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1]
    assert not (tmp_path / "o").exists()
