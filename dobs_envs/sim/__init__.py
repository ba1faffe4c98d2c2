"""Closed-loop simulation core (plant, exosystem, reference model, distributed observers)."""
from .dynamics import BACKENDS, estimates, estimation_errors, outputs, step_env
from .state import KernelArgs, SimParams, SimState

__all__ = ["SimParams", "SimState", "KernelArgs", "step_env", "estimates", "outputs", "estimation_errors", "BACKENDS"]
