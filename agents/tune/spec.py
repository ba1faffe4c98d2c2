"""What defines a study and where it is stored: :class:`StudySpec` (``study.json``; every trial receives it),
the output directory's entries, the reported metric, and the tuning-seeds-only check every trial repeats."""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

from ..config.envs import ENVS
from ..config.hyperparam_files import ALGOS
from ..training.seeds import EVALUATION, TUNING, check_episode_seeds, check_training_seeds

__all__ = ["StudySpec", "StudyDirError", "stored_spec", "read_study_json", "assert_tuning_only", "METRIC",
           "STUDY_FILES", "EXPERIMENT", "TRIAL_LOG"]


#: the reported score (lower is better): mean J_policy / J_paper over the tuning episodes
METRIC = "score"
#: the entries :func:`run_study` writes in its output directory
STUDY_FILES = ("study.json", "study", "trials.csv", "trials.png", "best.yml")
EXPERIMENT = "study"
#: the study's own record of its trials, inside ``EXPERIMENT``: one JSON object per line, appended by the driver as
#: Tune starts and ends a trial (plain JSON: what the table and a resume read instead of Tune's pickled state)
TRIAL_LOG = "trials.jsonl"


class StudyDirError(ValueError):
    """The output directory cannot take the study (occupied without resume/overwrite, nothing to resume,
    or a definition that differs from the stored one)."""


@dataclass(frozen=True)
class StudySpec:
    """What defines a study (``study.json``): the trainable receives it with every trial."""

    env: str
    algo: str
    trials: int
    timesteps: int
    episodes: int = 5
    tune_seed: int = TUNING.start
    seed: int = 0
    report_points: int = 6
    cpus_per_trial: int = 1
    hyperparams: dict = field(default_factory=dict)
    env_kwargs: dict = field(default_factory=dict)

    @property
    def episode_seeds(self) -> list[int]:
        return list(range(self.tune_seed, self.tune_seed + self.episodes))

    @property
    def report_every(self) -> int:
        return max(1, self.timesteps // self.report_points)

    def check(self) -> None:
        """ValueError naming the argument for anything out of range (before Ray starts)."""
        if self.env not in ENVS:
            raise ValueError(f"env must be one of {sorted(ENVS)}, got {self.env!r}")
        if self.algo not in ALGOS:
            raise ValueError(f"algo must be one of {ALGOS}, got {self.algo!r}")
        for name in ("trials", "timesteps", "episodes", "report_points", "cpus_per_trial"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        check_training_seeds(self.seed, 1, name="seed")
        check_episode_seeds(self.tune_seed, self.episodes, TUNING, name="tune_seed")
        assert_tuning_only(self.episode_seeds)


def assert_tuning_only(seeds) -> None:
    """Tuning never sees an evaluation episode (agents/training/seeds.py): checked again inside every trial."""
    bad = [s for s in seeds if s in EVALUATION or s not in TUNING]
    if bad:
        raise AssertionError(f"tuning episodes {bad} lie outside the {TUNING} (the {EVALUATION} is the "
                             f"benchmark's and never used for tuning)")


def read_study_json(out: str) -> dict:
    path = os.path.join(out, "study.json")
    try:
        with open(path) as fh:
            d = json.load(fh)
        return d if isinstance(d, dict) else {}
    except (OSError, ValueError):
        return {}


def stored_spec(out: str) -> StudySpec:
    """The :class:`StudySpec` recorded in ``out/study.json`` (StudyDirError if there is none)."""
    d = read_study_json(out).get("spec")
    if not isinstance(d, dict):
        raise StudyDirError(f"{out!r} holds no study to resume (study.json of dobs-envs tune)")
    try:
        return StudySpec(**d)
    except TypeError as exc:
        raise StudyDirError(f"{out}/study.json: {exc}") from None
