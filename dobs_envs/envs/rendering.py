"""Rendering: a plot of the error norms so far (matplotlib, imported lazily).

- ``render_mode="rgb_array"``: :func:`error_plot` draws it off-screen (Agg) and returns the image.
- ``render_mode="human"``: :class:`LivePlot` keeps it in a live matplotlib window, redrawn by
  ``reset``/``step`` (at most ``render_fps`` times a second) and by ``render()`` (which returns
  ``None``). On a machine without a display (a non-interactive backend such as Agg, or a GUI
  backend that cannot open a window) it warns once (``UserWarning``) and shows nothing; it never
  raises.
"""
from __future__ import annotations

import time
import warnings

import numpy as np

__all__ = ["error_plot", "LivePlot", "is_interactive_backend"]


_FLOOR = 1e-12


def _draw(ax, t, tracking, est, title: str, tracking_label: str) -> list:
    """The error plot on the axes ``ax`` (log y axis; non-positive values clipped to 1e-12 for display);
    returns the lines (tracking first)."""
    lines = ax.plot(t, np.maximum(tracking, _FLOOR), color="k", lw=1.6, label=tracking_label)
    est = np.atleast_2d(est)
    if est.size:
        for i in range(est.shape[1]):
            lines += ax.plot(t, np.maximum(est[:, i], _FLOOR), lw=0.9, label=rf"$\|\hat x_{{{i}}} - x\|$")
    ax.set_yscale("log")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("error norm")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=3, loc="upper right")
    return lines


def error_plot(t, tracking, est, *, title: str = "", tracking_label: str = r"$\|x - x_r\|$",
               width: int = 640, height: int = 400) -> np.ndarray:
    """RGB image (height, width, 3) uint8 of ``tracking (T,)`` and ``est (T, N)`` against ``t (T,)``.

    Log scale on the y axis (errors span decades); non-positive values are
    clipped to 1e-12 for display only.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    dpi = 80
    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    _draw(ax, t, tracking, est, title, tracking_label)
    fig.tight_layout()
    canvas.draw()
    img = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    return img


def is_interactive_backend(backend: str) -> bool:
    """Whether matplotlib's ``backend`` can show windows (``"agg"``, ``"pdf"``, ... cannot; third-party
    ``module://`` backends are taken at their word)."""
    b = backend.lower()
    if b.startswith("module://"):
        return "inline" not in b
    try:  # matplotlib >= 3.9
        from matplotlib.backends import BackendFilter, backend_registry

        names = backend_registry.list_builtin(BackendFilter.INTERACTIVE)
    except ImportError:  # pragma: no cover - older matplotlib
        from matplotlib import rcsetup

        names = rcsetup.interactive_bk
    return b in {n.lower() for n in names}


class LivePlot:
    """``render_mode="human"``: the error plot of :func:`error_plot` in a live matplotlib window.

    Parameters
    ----------
    title, tracking_label : as :func:`error_plot`.
    fps : redraws per second at most for :meth:`update` (``force=True`` always redraws); the
        interval is counted from the end of the previous redraw, so a slow display (e.g. a
        virtual frame buffer) slows the simulation down by at most half.
    """

    def __init__(self, title: str = "", tracking_label: str = r"$\|x - x_r\|$", fps: float = 20.0):
        self.title, self.tracking_label = title, tracking_label
        self.min_interval = 1.0 / float(fps)
        self._fig = self._ax = self._plt = self._lines = None
        self._last = -np.inf
        #: False once the window could not be opened (headless) or was closed by the user
        self.active = True

    def _open(self) -> bool:
        try:
            import matplotlib.pyplot as plt

            backend = plt.get_backend()
            if not is_interactive_backend(backend):
                raise RuntimeError(f"matplotlib's backend is {backend!r}, which cannot show windows (no display?)")
            fig = plt.figure(self.title or "dobs_envs", figsize=(8, 5))
            ax = fig.add_subplot(1, 1, 1)
            plt.show(block=False)
        except Exception as exc:  # headless: a warning, never an error
            self.active = False
            warnings.warn(f"render_mode='human' cannot open a window ({exc}); nothing is shown and render() "
                          f"returns None. On a machine without a display use render_mode='rgb_array' (images); "
                          f"with a display, choose a GUI backend (e.g. MPLBACKEND=TkAgg or QtAgg).",
                          UserWarning, stacklevel=5)
            return False
        self._plt, self._fig, self._ax = plt, fig, ax
        return True

    def update(self, t, tracking, est, *, force: bool = False) -> None:
        """Redraw with the history ``t (T,)``, ``tracking (T,)``, ``est (T, N)`` (throttled to ``fps``)."""
        if not self.active:
            return
        now = time.perf_counter()
        if not force and now - self._last < self.min_interval:
            return
        if self._fig is None:
            if not self._open():
                return
        elif not self._plt.fignum_exists(self._fig.number):  # closed by the user: stop drawing
            self.active = False
            self._fig = self._ax = self._lines = None
            return
        t, tracking, est = np.asarray(t), np.asarray(tracking), np.atleast_2d(np.asarray(est))
        ax = self._ax
        if self._lines is None or len(self._lines) != 1 + est.shape[1]:
            ax.clear()
            self._lines = _draw(ax, t, tracking, est, self.title, self.tracking_label)
        else:  # new data on the same lines (cheaper than redrawing the axes)
            self._lines[0].set_data(t, np.maximum(tracking, _FLOOR))
            for i, line in enumerate(self._lines[1:]):
                line.set_data(t, np.maximum(est[:, i], _FLOOR))
            ax.relim()
            ax.autoscale_view()
        self._fig.canvas.draw_idle()
        self._fig.canvas.flush_events()
        self._last = time.perf_counter()

    def __getstate__(self) -> dict:  # a copy of an environment opens its own window
        return {**self.__dict__, "_fig": None, "_ax": None, "_plt": None, "_lines": None, "_last": -np.inf}

    def close(self) -> None:
        """Close the window (if any)."""
        if self._fig is not None:
            self._plt.close(self._fig)
        self._fig = self._ax = None
