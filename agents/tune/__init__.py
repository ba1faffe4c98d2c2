"""``dobs-envs tune``: hyperparameter search of a recipe with Ray Tune (:mod:`agents.tune.study`)."""
