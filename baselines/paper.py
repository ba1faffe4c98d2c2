"""The paper's separation-based controllers (re-exported from :mod:`dobs_envs.control.laws`).

The laws -- eqs. (linearfeedback), (idealslidinglaw) with (hfunc), (hepsfunc) and
(adlawbeta) -- live in the library so that the environments can calibrate their
action bounds without importing ``baselines``; this module keeps the historical
import path ``from baselines.paper import SeparationController``.
:mod:`baselines.policies` wraps the same laws as env-API policies.
"""
from dobs_envs.control.laws import ControllerState, PrescribedInput, SeparationController, h, h_eps, paper_policy

__all__ = ["ControllerState", "SeparationController", "PrescribedInput", "h", "h_eps", "paper_policy"]
