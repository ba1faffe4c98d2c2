"""What the agents are configured by: environment names (:mod:`agents.config.envs`) and the
hyperparameter files (:mod:`agents.config.hyperparam_files`, the YAML files in ``hyperparams/``)."""
