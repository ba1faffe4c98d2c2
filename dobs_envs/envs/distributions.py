"""What a reset draws for one copy: the initial plant state and the unknown input.

Every copy of the batched core has its own ``numpy.random.Generator``; a reset of
copy ``c`` calls :meth:`ResetDistribution.x0` then :meth:`ResetDistribution.disturbance`
with that generator, in this order, so a copy seeded with ``s`` draws exactly what a
single environment reset with ``seed=s`` draws.

- Initial state: the scenario's ``x0_scale`` distribution ``U[-s, s]^n`` when it has one
  and ``init_noise`` is None, else ``x0 + U[-a, a]^n`` with ``a = init_noise`` (default 1.0).
- Unknown input ``v`` (systems with ``B_v``):

  * ``"exosystem"``: ``v(0) = expm(S tau) v0`` with a random time shift
    ``tau ~ U[0, 4 pi]`` (a random phase of the scenario's exosystem trajectory); a
    constant ``v0`` when the scenario has no (or a zero) exosystem;
  * ``"random"``: per component ``v_j(t) = sum_{l<3} a_jl sin(w_jl t + phi_jl)``,
    ``w_jl ~ U[0.1, 2]``, ``phi_jl ~ U[0, 2 pi]``, ``a_jl >= 0`` with
    ``sum_l a_jl = disturbance_amplitude`` (so ``|v_j(t)| <= disturbance_amplitude``),
    evaluated at the start of every control period and held (ZOH);
  * ``"none"``: ``v = 0``.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from ..linalg.validation import as_array

__all__ = ["ResetDistribution", "N_RANDOM_TERMS", "DEFAULT_INIT_NOISE", "random_signal"]

#: sinusoids per component of the "random" disturbance
N_RANDOM_TERMS = 3
#: default half-width of the uniform noise added to the scenario's x0 at reset
DEFAULT_INIT_NOISE = 1.0


def random_signal(a, w, ph, t):
    """``v_j(t) = sum_l a_jl sin(w_jl t + ph_jl)`` for parameters of shape ``(m_v, L)`` (numpy)."""
    return (a * np.sin(w * t + ph)).sum(axis=1)


class ResetDistribution:
    """Per-copy draws of a reset (see module docstring).

    Parameters
    ----------
    scenario : Scenario
    init_noise : float or None
    disturbance : "exosystem", "random" or "none" (resolved: "none" without ``B_v``)
    amplitude : float, bound of the "random" disturbance
    """

    def __init__(self, scenario, init_noise, disturbance: str, amplitude: float):
        self.scenario = scenario
        self.n = scenario.n_states
        self.m_v = scenario.B_v.shape[1]
        self.init_noise = init_noise
        self.disturbance = disturbance
        self.amplitude = float(amplitude)
        S = scenario.exosystem
        self._exo = S is not None and bool(np.any(S))

    def x0(self, rng: np.random.Generator) -> np.ndarray:
        """Initial plant state ``(n,)``."""
        sc = self.scenario
        if self.init_noise is None and sc.x0_scale is not None:
            return sc.sample_x0(rng)
        a = DEFAULT_INIT_NOISE if self.init_noise is None else self.init_noise
        return sc.x0 + rng.uniform(-a, a, size=self.n)

    def disturbance_params(self, rng: np.random.Generator, v0=None):
        """``(v(0) (m_v,), signal)``: ``signal = (a, w, ph)`` each ``(m_v, N_RANDOM_TERMS)`` for the
        "random" disturbance, else None. ``v0`` (exact initial unknown input) is validated here."""
        m_v = self.m_v
        if m_v == 0 or self.disturbance == "none":
            if v0 is not None and m_v:
                raise ValueError("options['v0'] is not used with disturbance='none'")
            return np.zeros(m_v), None
        if self.disturbance == "random":
            if v0 is not None:
                raise ValueError("options['v0'] is not used with disturbance='random' (v(t) is a random signal)")
            w = rng.uniform(0.1, 2.0, size=(m_v, N_RANDOM_TERMS))
            ph = rng.uniform(0.0, 2 * np.pi, size=(m_v, N_RANDOM_TERMS))
            a = rng.uniform(0.0, 1.0, size=(m_v, N_RANDOM_TERMS))
            a = self.amplitude * a / a.sum(axis=1, keepdims=True)  # sum_l |a_jl| = A  =>  |v_j(t)| <= A
            return random_signal(a, w, ph, 0.0), (a, w, ph)
        if v0 is not None:
            return as_array(v0, "options['v0']", shape=(m_v,)), None
        if not self._exo:
            return np.array(self.scenario.v0, dtype=np.float64), None
        tau = rng.uniform(0.0, 4 * np.pi)  # random time shift of the exosystem trajectory
        return expm(self.scenario.exosystem * tau) @ self.scenario.v0, None
