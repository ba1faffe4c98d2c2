"""The paper's control laws on estimate arrays (library layer; see :mod:`.laws`)."""
from .laws import ControllerState, PrescribedInput, SeparationController, h, h_eps, paper_policy

__all__ = ["ControllerState", "SeparationController", "PrescribedInput", "h", "h_eps", "paper_policy"]
