"""The paper's separation-based control laws, batched over environments.

Controller node ``k`` applies its law to the estimate ``xhat_{links[k]}`` of the
observer node it is linked to (C-O links are configuration; ``N_c != N`` is
allowed). With ``u = col(u^k)``, ``K = col(K^k)`` and ``B = [B^1 ... B^Nc]``:

- linear feedback, Theorem lfthm, eq. (linearfeedback): ``u^k = K^k xhat``
- tracking, Theorem reftrackthm: ``u^k = K^k xhat + r^k(t)``
- ideal sliding mode, Theorem smthm, eq. (idealslidinglaw):
  ``u^k = K^k xhat - beta^k h((B^k)^T P xhat)`` with ``h`` of eq. (hfunc)
- adaptive boundary-layer sliding mode, Theorem adsmthm:
  ``u^k = K^k xhat - beta^k h_eps^k((B^k)^T P xhat)`` (eq. hepsfunc) with
  ``beta^k' = -sigma^k beta^k + phi^k ||(B^k)^T P xhat||`` (eq. adlawbeta, the
  leakage law of (gagasbeta)).
- open loop (NE1): prescribed inputs ``u(t)`` (:class:`PrescribedInput`).

Stateful controllers keep their state explicitly (:class:`ControllerState`);
``act`` is pure. Over a control period ``T`` the leakage law is integrated
exactly for the held argument: ``beta <- e^{-sigma T} beta + (1 - e^{-sigma T})/sigma * phi ||w||``
(``T phi ||w||`` when ``sigma = 0``), which is Euler's step to O(T^2) and
stable for any ``T``.

This module is part of the library (the environments calibrate their action
bounds with it, ``dobs-envs reproduce`` simulates with it); :mod:`baselines.paper`
re-exports it and :mod:`baselines.policies` wraps it as env-API policies.
Scenarios are duck-typed (any object with the :class:`~dobs_envs.scenarios.scenario.Scenario`
fields used here), so this module imports nothing from the rest of the package.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ControllerState", "SeparationController", "PrescribedInput", "h", "h_eps", "paper_policy"]


@dataclass(frozen=True)
class ControllerState:
    """``beta (B, Nc)``: adaptive sliding gains (constant for the other laws)."""

    beta: np.ndarray


def _channel_norms(w: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Euclidean norm of each channel's block of ``w (B, m)`` -> (B, Nc)."""
    return np.sqrt(np.add.reduceat(w * w, starts, axis=-1))


def h(w: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Eq. (hfunc) channel-wise: ``w / ||w||`` (0 at 0). ``w (B, m)``."""
    nrm = _channel_norms(w, starts)
    rep = np.repeat(nrm, np.diff(np.append(starts, w.shape[-1])), axis=-1)
    return np.where(rep > 0, w / np.where(rep > 0, rep, 1.0), 0.0)


def h_eps(w: np.ndarray, starts: np.ndarray, beta: np.ndarray, eps: float) -> np.ndarray:
    """Eq. (hepsfunc) channel-wise: ``w/||w||`` if ``beta ||w|| > eps`` else ``beta w / eps``."""
    widths = np.diff(np.append(starts, w.shape[-1]))
    nrm = np.repeat(_channel_norms(w, starts), widths, axis=-1)
    b = np.repeat(beta, widths, axis=-1)
    outer = b * nrm > eps
    return np.where(outer, w / np.where(nrm > 0, nrm, 1.0), b * w / eps)


class SeparationController:
    """One of the paper's controllers for all controller nodes at once.

    Parameters
    ----------
    kind : "feedback" | "tracking" | "sliding_mode" | "adaptive_sliding_mode"
    K : (m, n) stacked ``K^k``.
    B : (n, m) stacked channels ``[B^1 ... B^Nc]``.
    channel_slices : columns of each channel in ``B``/``u``.
    links : (Nc,) observer node used by controller node ``k``.
    reference : callable ``t (B,) -> r (B, m)`` (tracking only).
    P : (n, n) sliding-mode matrix (sliding modes only).
    beta0, sigma_beta, phi_beta, epsilon : eqs. (hepsfunc)/(adlawbeta); for
        "sliding_mode" ``beta0`` is the fixed gain ``beta^k``.
    """

    KINDS = ("feedback", "tracking", "sliding_mode", "adaptive_sliding_mode")

    def __init__(self, kind, K, B, channel_slices, links, *, reference=None, P=None,
                 beta0=0.1, sigma_beta=0.1, phi_beta=5.0, epsilon=0.2):
        if kind not in self.KINDS:
            raise ValueError(f"kind must be one of {self.KINDS}, got {kind!r}")
        self.kind = kind
        self.K = np.array(K, dtype=float)
        self.B = np.array(B, dtype=float)
        m, n = self.K.shape
        if self.B.shape != (n, m):
            raise ValueError(f"B must have shape ({n}, {m}) to match K {self.K.shape}, got {self.B.shape}")
        self.channel_slices = tuple(channel_slices)
        self.starts = np.array([s.start for s in self.channel_slices])
        widths = [s.stop - s.start for s in self.channel_slices]
        if sum(widths) != m:
            raise ValueError("channel_slices must partition the m input columns")
        self.links = np.asarray(links, dtype=int)
        if self.links.shape != (len(self.channel_slices),):
            raise ValueError(f"links must give one observer node per controller node ({len(self.channel_slices)}), got {self.links.shape}")
        self.row_link = np.repeat(self.links, widths)  # observer node feeding input row j
        if kind == "tracking" and reference is None:
            raise ValueError("tracking controller needs a reference r(t)")
        self.reference = reference
        if kind in ("sliding_mode", "adaptive_sliding_mode"):
            if P is None:
                raise ValueError(f"{kind} controller needs P")
            self.BtP = self.B.T @ np.asarray(P, dtype=float)  # rows: (B^k)^T P
        else:
            self.BtP = None
        self.beta0 = float(beta0)
        self.sigma_beta = float(sigma_beta)
        self.phi_beta = float(phi_beta)
        self.epsilon = float(epsilon)

    @classmethod
    def from_scenario(cls, sc, kind: str | None = None) -> "SeparationController":
        kind = kind or sc.controller
        return cls(kind, sc.K, sc.B, sc.channel_slices, sc.links, reference=sc.reference, P=sc.P,
                   beta0=sc.beta0, sigma_beta=sc.sigma_beta, phi_beta=sc.phi_beta, epsilon=sc.epsilon)

    @property
    def n_controllers(self) -> int:
        return len(self.channel_slices)

    def initial_state(self, batch: int = 1) -> ControllerState:
        return ControllerState(beta=np.full((batch, self.n_controllers), self.beta0))

    def linked_estimates(self, xhat: np.ndarray) -> np.ndarray:
        """``xhat (B, N, n)`` -> per input row the estimate it uses, (B, m, n)."""
        return xhat[:, self.row_link, :]

    def act(self, xhat: np.ndarray, t: np.ndarray, cstate: ControllerState, period: float):
        """Control input for all controller nodes.

        Parameters
        ----------
        xhat : (B, N, n) all observer nodes' estimates (only the linked ones are used).
        t : (B,) time. cstate : ControllerState. period : control period (s), for beta.

        Returns
        -------
        u : (B, m), new ControllerState
        """
        r = self.reference(t) if self.kind == "tracking" else None
        return self.act_rows(self.linked_estimates(xhat), r, cstate, period)

    def act_rows(self, xl: np.ndarray, r, cstate: ControllerState, period: float):
        """The control laws given, for every input row ``j``, the estimate its
        controller node uses: ``xl (B, m, n)``; ``r (B, m)`` is the reference
        command (tracking only). This is the single implementation of the laws;
        :meth:`act`, the environments' action-bound calibration and
        :class:`baselines.policies.SeparationPolicy` call it.
        """
        u = np.einsum("jn,bjn->bj", self.K, xl)
        if self.kind == "tracking":
            u = u + r
        beta = cstate.beta
        if self.BtP is not None:
            w = np.einsum("jn,bjn->bj", self.BtP, xl)  # (B^k)^T P xhat_k, stacked
            widths = np.diff(np.append(self.starts, w.shape[-1]))
            if self.kind == "sliding_mode":
                u = u - np.repeat(beta, widths, axis=-1) * h(w, self.starts)
            else:
                u = u - np.repeat(beta, widths, axis=-1) * h_eps(w, self.starts, beta, self.epsilon)
                wn = _channel_norms(w, self.starts)
                s, T = self.sigma_beta, float(period)
                decay = np.exp(-s * T)
                gain = (1.0 - decay) / s if s > 0 else T
                beta = decay * beta + gain * self.phi_beta * wn
        return u, ControllerState(beta=beta)


class PrescribedInput:
    """Open-loop inputs ``u(t)`` (NE1: ``u_i = 0.5 (i-1) sin((6-i) t)``)."""

    def __init__(self, signal):
        self.signal = signal

    def initial_state(self, batch: int = 1) -> ControllerState:
        return ControllerState(beta=np.zeros((batch, 0)))

    def act(self, xhat, t, cstate, period):
        return self.signal(t), cstate


def paper_policy(sc):
    """The controller the paper applies in scenario ``sc``.

    Parameters
    ----------
    sc : Scenario
        Uses ``sc.controller`` ("open_loop" -> :class:`PrescribedInput` of
        ``sc.prescribed_input``; otherwise :meth:`SeparationController.from_scenario`).

    Returns
    -------
    PrescribedInput or SeparationController
        Both have ``initial_state(batch)`` and ``act(xhat (B, N, n), t (B,), cstate, period)
        -> (u (B, m), cstate)``.
    """
    if sc.controller == "open_loop":
        return PrescribedInput(sc.prescribed_input)
    return SeparationController.from_scenario(sc)
