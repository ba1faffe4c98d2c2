"""The import path of the seed ranges documented before issue 38 (``agents.seeds``); they live in
:mod:`agents.training.seeds`."""
from .training.seeds import (BC_DEMONSTRATION_OFFSET, EVALUATION, MAX_TRAINING_COPIES, RANGES, RESUME_OFFSET,
                             TRAINING, TUNING, SeedRange, check_episode_seeds, check_training_seeds, resume_seed)

__all__ = ["SeedRange", "TRAINING", "EVALUATION", "TUNING", "RANGES", "BC_DEMONSTRATION_OFFSET", "RESUME_OFFSET",
           "MAX_TRAINING_COPIES", "check_episode_seeds", "check_training_seeds", "resume_seed"]
