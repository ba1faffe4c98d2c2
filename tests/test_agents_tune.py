"""``dobs-envs tune`` (agents/tune/) on a real local Ray (``ray.init(num_cpus=2)``), real Optuna and
ASHA: a 3-trial study of a few hundred env steps writes trials.csv/png and a best.yml that ``train``
accepts; every episode a trial is scored on is a tuning episode, never an evaluation one; an
interrupted study (SIGINT, Tune's own Ctrl-C handling) resumes without running finished trials again, from its own
JSON records: no pickle in the study directory is ever loaded."""
from __future__ import annotations

import hashlib
import json
import glob
import os
import pickle
import signal
from dataclasses import asdict

import pytest

ray = pytest.importorskip("ray")
pytest.importorskip("ray.tune")
pytest.importorskip("optuna")

from agents.config.envs import gym_id  # noqa: E402
from agents.config.hyperparam_files import read_hyperparams_file  # noqa: E402
from agents.training.recipes import resolve_recipe  # noqa: E402
from agents.training.seeds import EVALUATION, TRAINING, TUNING  # noqa: E402
from agents.tune.space import SearchSpace  # noqa: E402
from agents.tune.spec import StudyDirError, StudySpec  # noqa: E402
from agents.tune.study import run_study  # noqa: E402
from dobs_envs.cli import main  # noqa: E402

# tiny: 2 env copies, 512 env steps per trial (rollouts of 64 x 2), 2 tuning episodes of 20 control periods
SPEC = StudySpec(env="hetero_mas", algo="ppo", trials=3, timesteps=512, episodes=2, report_points=2,
                 hyperparams={"n_envs": 2}, env_kwargs={"max_cycles": 20})


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def study(local_ray, tmp_path_factory):
    out = str(tmp_path_factory.mktemp("tune") / "study")
    res = run_study(SPEC, out, progress=False)
    assert res.complete
    return res


def _trial_dirs(out):
    exp = os.path.join(out, "study")
    return sorted(os.path.join(exp, d) for d in os.listdir(exp) if d.startswith("trial_"))


def test_study_writes_table_figure_and_a_complete_rl_zoo3_section(study):
    out = study.out
    for f in ("study.json", "trials.csv", "trials.png", "best.yml"):
        assert os.path.getsize(os.path.join(out, f)) > 0, f
    rows = study.rows
    assert len(rows) == 3 and all(r["status"] in ("complete", "stopped early") for r in rows)
    complete = [r for r in rows if r["status"] == "complete"]
    assert complete and all(r["env_steps"] >= SPEC.timesteps for r in complete)
    assert study.best["score"] == min(r["score"] for r in complete)
    for r in complete:  # a finished run is kept whole (the last score is reported after the save)
        assert os.path.exists(os.path.join(out, r["path"], "run", "model.zip"))
    with open(os.path.join(out, "trials.csv")) as fh:
        assert len(fh.read().strip().splitlines()) == 1 + 3
    # the best trial's recipe: the section rl-zoo3 reads for the env, complete (every key of ppo.yaml's default)
    table = read_hyperparams_file(os.path.join(out, "best.yml"))
    assert list(table) == [gym_id("hetero_mas")]
    sec = table[gym_id("hetero_mas")]
    default = resolve_recipe("ppo", "default").hyperparams
    assert set(default) <= set(sec)
    b = study.best
    assert sec["n_steps"] == b["n_steps"] and sec["gamma"] == b["gamma"] and sec["n_envs"] == 2
    assert sec["policy_kwargs"]["net_arch"] == [int(w) for w in b["net_arch"].split("x")]
    assert sec["policy_kwargs"]["activation_fn"] == "tanh"  # the recipe's, kept under the searched net_arch
    assert sec["env_kwargs"]["state_bound"] == b["state_bound"]
    lr = sec["learning_rate"]
    assert (lr.startswith("lin_") and b["lr_schedule"] == "linear") or (lr == pytest.approx(b["learning_rate"]))
    head = open(os.path.join(out, "best.yml")).read().split("\n" + gym_id("hetero_mas") + ":")[0]
    assert "tuning episodes 20000-20001" in head and "3 trials" in head


def test_trials_are_scored_on_tuning_episodes_only(study):
    dirs = _trial_dirs(study.out)
    assert len(dirs) == 3
    for d in dirs:
        with open(os.path.join(d, "curve.json")) as fh:
            curve = json.load(fh)
        assert curve["seeds"] == [20000, 20001]
        assert all(s in TUNING and s not in EVALUATION for s in curve["seeds"])
        assert len(curve["points"]) >= 2
        with open(os.path.join(d, "run", "config.json")) as fh:
            cfg = json.load(fh)
        assert cfg["seed"] == SPEC.seed and cfg["seed"] in TRAINING


def test_train_accepts_the_best_recipe(study, tmp_path):
    best = os.path.join(study.out, "best.yml")
    out = str(tmp_path / "run")
    assert main(["train", "--env", "hetero_mas", "--algo", "ppo", "--recipe", best, "--timesteps", "128",
                 "--out", out, "--no-progress", "--hyperparams", '{"n_epochs": 1}']) == 0
    with open(os.path.join(out, "config.json")) as fh:
        cfg = json.load(fh)
    sec = read_hyperparams_file(best)[gym_id("hetero_mas")]
    hp = cfg["hyperparams"]
    for k in ("n_steps", "batch_size", "gamma", "learning_rate", "n_envs", "use_sde"):
        assert hp[k] == sec[k], k
    assert hp["n_epochs"] == 1  # --hyperparams apply over the recipe file
    assert hp["policy_kwargs"] == sec["policy_kwargs"]
    assert cfg["train_env_kwargs"]["state_bound"] == sec["env_kwargs"]["state_bound"]
    assert cfg["status"] == "complete"


class _Payload:
    """Unpickling it writes the file ``path`` (what a hostile pickle in a study directory could do)."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (open, (self.path, "w"))


class _InterruptAfterFirstTrial:
    """A Tune callback sending the driver a real SIGINT (Ctrl-C) when the first trial finishes (once: a
    marker file)."""

    def __new__(cls, marker):
        from ray.tune import Callback

        class _Cb(Callback):
            def on_trial_complete(self, iteration, trials, trial, **info):
                if not os.path.exists(marker):
                    open(marker, "w").close()
                    os.kill(os.getpid(), signal.SIGINT)

        return _Cb()


def test_an_interrupted_study_resumes_without_repeating_finished_trials(local_ray, tmp_path):
    out = str(tmp_path / "study")
    res = run_study(SPEC, out, progress=False, callbacks=[_InterruptAfterFirstTrial(str(tmp_path / "fired"))])
    assert not res.complete
    done = [r for r in res.rows if r["status"] in ("complete", "stopped early")]
    assert 1 <= len(done) < 3 and not os.path.exists(os.path.join(out, "best.yml"))
    def history(row):  # the trial's reports (Tune's result.json) and its run's saved model
        with open(os.path.join(out, row["path"], "result.json")) as fh:
            reports = [(r["timestamp"], r["env_steps"], r["score"]) for r in map(json.loads, fh)]
        model = os.path.join(out, row["path"], "run", "model.zip")  # Tune copies trial files (mtimes change)
        return reports, hashlib.sha256(open(model, "rb").read()).hexdigest() if os.path.exists(model) else None

    before = {r["trial_id"]: history(r) for r in done}
    assert all(before[r["trial_id"]][1] is not None for r in done if r["status"] == "complete")
    # the directory is the user's to give: every pickle Tune left in it (its experiment state, the searcher's) is
    # replaced by one that would leave a marker file if it were unpickled; Tune's JSON state by one that names a
    # cloudpickle payload. A resume reads none of them.
    marker = tmp_path / "unpickled"
    payload = pickle.dumps(_Payload(str(marker)))
    pkls = glob.glob(os.path.join(out, "study", "*.pkl"))
    assert pkls  # Tune wrote some: the test replaces real files
    for f in pkls:
        with open(f, "wb") as fh:
            fh.write(payload)
    for f in glob.glob(os.path.join(out, "study", "experiment_state*.json")):
        with open(f, "w") as fh:
            json.dump({"_type": "CLOUDPICKLE_FALLBACK", "value": payload.hex()}, fh)
    with open(os.path.join(out, "study", "trials.jsonl"), "a") as fh:
        fh.write('{"event": "complete", "trial_')  # a torn last line (a study killed while writing) is skipped
    res2 = run_study(SPEC, out, resume=True, progress=False)
    assert not marker.exists()
    assert res2.complete and len(res2.rows) == 3
    # an unfinished trial runs again with its own values, as a new trial; the table leaves the old one out
    with open(os.path.join(out, "study", "trials.jsonl")) as fh:
        events = [json.loads(line) for line in fh if line.strip().endswith("}")]
    configs = {e["trial_id"]: e["config"] for e in events if e["event"] == "start"}
    ids = {r["trial_id"] for r in res2.rows}
    for r in res.rows:
        if r["status"] == "unfinished":
            assert r["trial_id"] not in ids
            assert any(configs[i] == configs[r["trial_id"]] for i in ids - set(before))
    assert os.path.exists(os.path.join(out, "best.yml"))
    # rows keep the order the trials were created; ``trial`` numbers the rows, so a trial that finished after an
    # unfinished (superseded) one moves up by one: its trial_id is what stays
    assert [r["trial_id"] for r in res2.rows if r["trial_id"] in before] == [r["trial_id"] for r in done]
    assert [r["trial"] for r in res2.rows] == list(range(len(res2.rows)))
    for tid, h in before.items():  # a finished trial was not run again: same reports, same saved model
        assert history(next(r for r in res2.rows if r["trial_id"] == tid)) == h


def test_search_space_holds_todays_recipe_and_maps_back_to_it():
    """The first trial of a real study is today's recipe: its values lie in the space, and the overrides of
    that point leave the recipe unchanged."""
    for algo, env in (("ppo", "hetero_mas"), ("ppo", "tracking"), ("sac", "tracking")):
        r = resolve_recipe(algo, env)
        space = SearchSpace(algo, r.hyperparams, r.n_timesteps)
        point = space.baseline()
        assert point is not None, (algo, env)
        again = resolve_recipe(algo, env, overrides=space.overrides(point)).hyperparams
        lr = [h.pop("learning_rate") for h in (again, r.hyperparams)]  # "lin_0.0003" == "lin_3.0e-4"
        assert [float(str(v).removeprefix("lin_")) for v in lr] == [float(str(lr[1]).removeprefix("lin_"))] * 2
        assert [str(v).startswith("lin_") for v in lr] == [str(lr[1]).startswith("lin_")] * 2
        assert again.pop("use_sde", False) == r.hyperparams.pop("use_sde", False)  # False: SB3's default
        r.hyperparams["policy_kwargs"].setdefault("log_std_init", {"ppo": 0.0, "sac": -3.0}[algo])  # SB3's defaults
        assert again == r.hyperparams, (algo, env)
    td3 = resolve_recipe("td3", "tracking")
    assert {n for n, _, _ in SearchSpace("td3", td3.hyperparams, 50_000).params()} >= {
        "train_freq", "gradient_steps", "noise_std", "learning_rate", "state_bound"}


def test_evaluation_episodes_are_refused():
    with pytest.raises(ValueError, match="tuning range"):
        StudySpec(env="tracking", algo="ppo", trials=1, timesteps=10, tune_seed=EVALUATION.start).check()
    with pytest.raises(ValueError, match="tuning range"):  # runs into the evaluation range from below
        StudySpec(env="tracking", algo="ppo", trials=1, timesteps=10, tune_seed=TUNING.stop - 1, episodes=2).check()


def _exit2(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err.strip()
    assert exc.value.code == 2, err
    assert "Traceback" not in err and err.count("\n") == 0, err
    return err


def test_cli_usage_errors(tmp_path, capsys):
    occupied = tmp_path / "occupied"
    occupied.mkdir()
    (occupied / "notes.txt").write_text("x")
    assert "--overwrite" in _exit2(["tune", "--out", str(occupied)], capsys)
    assert "no study to resume" in _exit2(["tune", "--out", str(occupied), "--resume"], capsys)
    assert "tuning range" in _exit2(["tune", "--out", str(tmp_path / "n"), "--tune-seed", "10000"], capsys)
    assert "give one of them" in _exit2(["tune", "--out", str(occupied), "--resume", "--overwrite"], capsys)
    assert "--cpus" in _exit2(["tune", "--out", str(tmp_path / "n"), "--address", "auto", "--cpus", "2"], capsys)
    assert "--recipe" in _exit2(["train", "--env", "tracking", "--recipe", str(tmp_path / "none.yml"),
                                 "--out", str(tmp_path / "r")], capsys)
    (occupied / "study.json").write_text(json.dumps({"spec": asdict(SPEC)}))
    (occupied / "study").mkdir()
    err = _exit2(["tune", "--out", str(occupied), "--resume", "--algo", "sac"], capsys)
    assert "--algo sac (the study has ppo)" in err
    with pytest.raises(StudyDirError, match="before its first trial started"):  # the same study, no trial log
        run_study(SPEC, str(occupied), resume=True, progress=False)
    (occupied / "study" / "trial_0123abcd").mkdir()  # trials but no log: never resumed from Tune's pickles
    with pytest.raises(StudyDirError, match="not resumed from Ray Tune's pickled state"):
        run_study(SPEC, str(occupied), resume=True, progress=False)
    err = _exit2(["tune", "--out", str(tmp_path / "n"), "--hyperparams", '{"n_stepz": 8}'], capsys)
    assert "PPO takes no argument(s) ['n_stepz']" in err
    assert not os.path.exists(tmp_path / "n")
