"""Scenarios: the single extension point of the suite.

* :class:`Scenario` (``base``), :class:`Sinusoids` (``signals``);
* the paper's examples :func:`ne1`, :func:`ne2`, :func:`ne2_ablation`, :func:`ne3` (``paper``);
* seeded random systems :func:`random_mas_scenario`, :func:`random_plant_scenario`,
  :func:`random_scenario` (``random``);
* YAML/JSON files :func:`load_scenario`, :func:`save_scenario` (``io``);
* the cooperative MAS task :func:`rendezvous_scenario` (``mas_tasks``);
* a name -> factory registry: :data:`SCENARIOS`, :func:`make_scenario`.
"""
from __future__ import annotations

import os
from typing import Callable

from .scenario import CONTROLLERS, Scenario
from .io import (
    EXAMPLES,
    ScenarioFileError,
    example_path,
    load_scenario,
    save_scenario,
    scenario_from_dict,
    scenario_to_dict,
)
from .mas_tasks import disagreement, rendezvous_cost, rendezvous_lqr, rendezvous_metrics, rendezvous_scenario
from .paper import PAPER_SCENARIOS, ne1, ne2, ne2_ablation, ne3
from .random import RandomScenarioError, random_mas_scenario, random_plant_scenario, random_scenario
from .signals import Sinusoids

__all__ = [
    "Scenario", "Sinusoids", "CONTROLLERS",
    "ne1", "ne2", "ne2_ablation", "ne3", "PAPER_SCENARIOS",
    "random_mas_scenario", "random_plant_scenario", "random_scenario", "RandomScenarioError",
    "load_scenario", "save_scenario", "scenario_from_dict", "scenario_to_dict", "ScenarioFileError",
    "example_path", "EXAMPLES",
    "rendezvous_scenario", "rendezvous_cost", "rendezvous_lqr", "rendezvous_metrics", "disagreement",
    "SCENARIOS", "make_scenario", "available_scenarios",
]


def _example(name: str) -> Callable[..., Scenario]:
    def factory(**overrides) -> Scenario:
        sc = load_scenario(example_path(name))
        return sc.replace(**overrides) if overrides else sc

    factory.__name__ = f"example_{name}"
    factory.__doc__ = f"The shipped example file ``{name}.yaml`` (keyword arguments replace Scenario fields)."
    return factory


#: name -> factory; every factory is callable without arguments and accepts
#: its own keyword arguments (e.g. ``seed=`` for the random ones).
SCENARIOS: dict[str, Callable[..., Scenario]] = {
    **PAPER_SCENARIOS,  # "ne1", "ne2", "ne2-ablation", "ne3"
    "ne1-rendezvous": rendezvous_scenario,
    "random-mas": random_mas_scenario,
    "random-plant": random_plant_scenario,
    "custom3": _example("custom3"),
}


def available_scenarios() -> list[str]:
    """Registered scenario names (sorted)."""
    return sorted(SCENARIOS)


def make_scenario(name: str, **kwargs) -> Scenario:
    """Build a scenario by registry name (:data:`SCENARIOS`) or from a ``.yaml``/``.yml``/``.json`` path.

    ``kwargs`` go to the factory (e.g. ``make_scenario("random-plant", seed=3, n_states=8)``);
    for a file they replace Scenario fields of the loaded scenario.
    """
    if name in SCENARIOS:
        return SCENARIOS[name](**kwargs)
    if os.path.splitext(str(name))[1].lower() in (".yaml", ".yml", ".json"):
        sc = load_scenario(name)
        return sc.replace(**kwargs) if kwargs else sc
    raise KeyError(f"unknown scenario {name!r}; registered names are {available_scenarios()} "
                   "(or pass a .yaml/.yml/.json path)")
