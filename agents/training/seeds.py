"""The seed ranges of the benchmark: training, tuning and model selection, evaluation (one place).

Every episode an agent is trained, tuned or evaluated on is reset with a seed; the three
uses never share one, so that nothing chosen while developing an agent (a recipe, a
learning-curve point, a training-only state bound) has seen the episodes the published
table is computed on:

=============  =================  ==================================================================
range          seeds              used for
=============  =================  ==================================================================
training       0 - 9 999          RL training seeds (``dobs-envs train --seed``, the benchmark's
                                  ``--seed``); the training env copy ``c`` of seed ``s`` is reset
                                  with ``s + c``, its later episodes continue that generator
tuning         20 000 - 29 999    tuning and model selection: learning curves (the benchmark's,
                                  from 20 000), recipe choices, training-only state bounds,
                                  ``dobs-envs evaluate`` by default
evaluation     10 000 - 19 999    the benchmark's evaluation episodes (``--eval-seed``, from
                                  10 000) and nothing else
=============  =================  ==================================================================

Training data outside these ranges: behaviour-cloning demonstrations (seed
``BC_DEMONSTRATION_OFFSET + s`` for training seed ``s``) and the episodes of a resumed run
(``RESUME_OFFSET + s + steps done``).
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SeedRange", "TRAINING", "EVALUATION", "TUNING", "RANGES", "BC_DEMONSTRATION_OFFSET",
           "RESUME_OFFSET", "MAX_TRAINING_COPIES", "check_episode_seeds", "check_training_seeds", "resume_seed"]


@dataclass(frozen=True)
class SeedRange:
    """Seeds ``start <= s < stop`` reserved for one use."""

    name: str
    start: int
    stop: int

    def __contains__(self, seed) -> bool:
        return self.start <= seed < self.stop

    def holds(self, first: int, count: int) -> bool:
        """Whether the seeds ``first .. first + count - 1`` all lie in the range."""
        return self.start <= first and first + count <= self.stop

    def __str__(self) -> str:
        return f"{self.name} range {self.start}-{self.stop - 1}"


TRAINING = SeedRange("training", 0, 10_000)
EVALUATION = SeedRange("evaluation", 10_000, 20_000)
TUNING = SeedRange("tuning", 20_000, 30_000)
RANGES = (TRAINING, EVALUATION, TUNING)

#: behaviour-cloning demonstrations of training seed ``s`` are reset with ``BC_DEMONSTRATION_OFFSET + s + k``
BC_DEMONSTRATION_OFFSET = 10_000_000
#: a resumed run's environments restart with seed ``RESUME_OFFSET + s + steps done`` (never an evaluation
#: or tuning episode; the generator seeds stay below 2**32)
RESUME_OFFSET = 1_000_000_000
#: the most environment copies a recipe trains with; a training seed ``s`` uses ``s .. s + copies - 1``
MAX_TRAINING_COPIES = 64


def _check_int(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    return int(value)


def check_episode_seeds(first, count, use: SeedRange, *, name: str = "seed") -> list[int]:
    """The seeds ``first .. first + count - 1``, which must all lie in ``use`` (ValueError naming
    ``name`` and the range otherwise)."""
    first, count = _check_int(name, first), _check_int("episodes", count)
    if count < 1:
        raise ValueError(f"episodes must be >= 1, got {count}")
    if not use.holds(first, count):
        others = ", ".join(str(r) for r in RANGES if r is not use)
        raise ValueError(f"{name} {first} with {count} episode(s) uses seeds {first}-{first + count - 1}, outside the "
                         f"{use} ({others}: agents/training/seeds.py)")
    return list(range(first, first + count))


def check_training_seeds(first, count, *, name: str = "seed") -> list[int]:
    """Training seeds ``first .. first + count - 1``; with their env copies
    (:data:`MAX_TRAINING_COPIES`) they must stay in :data:`TRAINING`."""
    first, count = _check_int(name, first), _check_int("seeds", count)
    if count < 1:
        raise ValueError(f"seeds must be >= 1, got {count}")
    if not TRAINING.holds(first, count + MAX_TRAINING_COPIES - 1):
        raise ValueError(f"{name} {first} with {count} training seed(s) leaves the {TRAINING} (each seed's env "
                         f"copies use up to {MAX_TRAINING_COPIES} consecutive seeds; the {EVALUATION} and "
                         f"{TUNING} are reserved: agents/training/seeds.py)")
    return list(range(first, first + count))


def resume_seed(seed: int, steps_done: int) -> int:
    """The seed a run of training seed ``seed`` resumed after ``steps_done`` environment steps restarts
    its environments with: outside the evaluation and tuning ranges."""
    return RESUME_OFFSET + int(seed) + int(steps_done)
