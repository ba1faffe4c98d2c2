"""Exogenous signals of the scenarios: reference commands ``r^k`` (eq. refxdy)
and prescribed open-loop inputs (NE1), as banks of sinusoids."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..linalg.validation import as_array

__all__ = ["Sinusoids"]


@dataclass(frozen=True)
class Sinusoids:
    """``s_j(t) = amplitude_j * sin(frequency_j * t + phase_j)`` for ``j = 0..m-1``.

    NE2's reference ``r^k = sin(t + k)`` (k = 1..5) is
    ``Sinusoids(amplitude=ones, frequency=ones, phase=[1, 2, 3, 4, 5])``; NE1's
    inputs ``u_i = 0.5 (i-1) sin((6-i) t)`` are
    ``Sinusoids(amplitude=0.5*[0..4], frequency=[5, 4, 3, 2, 1], phase=0)``.
    """

    amplitude: tuple
    frequency: tuple
    phase: tuple

    def __post_init__(self):
        # bool, strings, ragged lists and numbers beyond the float range: named errors (shared validator)
        a, w, ph = (np.atleast_1d(as_array(getattr(self, n), f"Sinusoids: {n}"))
                    for n in ("amplitude", "frequency", "phase"))
        m = max(a.size, w.size, ph.size)
        try:
            a, w, ph = (np.broadcast_to(v, (m,)) for v in (a, w, ph))
        except ValueError:
            raise ValueError(f"Sinusoids: amplitude/frequency/phase lengths {a.size}/{w.size}/{ph.size} do not broadcast") from None
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(w)) and np.all(np.isfinite(ph))):
            raise ValueError("Sinusoids: parameters must be finite")
        object.__setattr__(self, "amplitude", tuple(float(x) for x in a))
        object.__setattr__(self, "frequency", tuple(float(x) for x in w))
        object.__setattr__(self, "phase", tuple(float(x) for x in ph))

    @property
    def size(self) -> int:
        return len(self.amplitude)

    @property
    def bound(self) -> float:
        """Euclidean-norm bound ``sup_t ||s(t)||`` (Assumptions 1-2 need boundedness)."""
        return float(np.linalg.norm(self.amplitude))

    def __call__(self, t) -> np.ndarray:
        """Values at times ``t`` (scalar or (B,)); returns (m,) or (B, m)."""
        t = np.asarray(t, dtype=float)
        a, w, ph = (np.asarray(v) for v in (self.amplitude, self.frequency, self.phase))
        return a * np.sin(w * t[..., None] + ph)

    def to_dict(self) -> dict:
        return {"amplitude": list(self.amplitude), "frequency": list(self.frequency), "phase": list(self.phase)}
