"""``render_mode="rgb_array"``: a plot of the error norms so far (matplotlib Agg, imported lazily)."""
from __future__ import annotations

import numpy as np

__all__ = ["error_plot"]


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
    floor = 1e-12
    ax.plot(t, np.maximum(tracking, floor), color="k", lw=1.6, label=tracking_label)
    est = np.atleast_2d(est)
    if est.size:
        for i in range(est.shape[1]):
            ax.plot(t, np.maximum(est[:, i], floor), lw=0.9, label=rf"$\|\hat x_{{{i}}} - x\|$")
    ax.set_yscale("log")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("error norm")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=3, loc="upper right")
    fig.tight_layout()
    canvas.draw()
    img = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    return img
