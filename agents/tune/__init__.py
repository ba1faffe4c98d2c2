"""``dobs-envs tune``: hyperparameter search of a recipe with Ray Tune (Optuna's TPE sampler, ASHA).

:mod:`~agents.tune.study` (:func:`~agents.tune.study.run_study`: the trials, resuming, the trainable),
:mod:`~agents.tune.space` (:class:`~agents.tune.space.SearchSpace`), :mod:`~agents.tune.spec` (the study's
definition, ``study.json``, its output directory) and :mod:`~agents.tune.outputs` (``trials.csv``, ``trials.png``,
``best.yml``).

The names of the module ``agents.tune`` before issue 38 are still found here, imported on first use: the import
path of scripts, and the references Ray Tune pickled into an interrupted study's experiment (its search space and
trial-directory function), so that ``--resume`` continues a study started before the split.
"""
from .._moved import moved_names

#: name -> the module that defines it (the names of the former module agents/tune.py)
_MOVED = {
    **dict.fromkeys(("run_study", "StudyResult", "check_constructor_keys", "_trial", "_trial_dirname"), "study"),
    **dict.fromkeys(("SearchSpace", "NETS"), "space"),
    **dict.fromkeys(("StudySpec", "StudyDirError", "stored_spec", "STUDY_FILES", "METRIC"), "spec"),
    **dict.fromkeys(("write_best_recipe", "trials_table", "recipe_section"), "outputs"),
}

__getattr__, __dir__ = moved_names(__name__, _MOVED)
