"""Run plot (thesis Fig. 3.8): the path on the track, speed and steering over time -> PNG.

matplotlib with the Agg backend (no display needed); the figure is closed after saving.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from simrunner.errors import SimError
from simrunner.run.log import RunLog


def plot_run(log: RunLog, track, path: str | Path, *, title: str = "") -> Path:
    """Write a 3-panel PNG: path over the track raster (``track``: a ``SimTrack`` or None),
    speed (actual and commanded, m/s) and steering (actual and commanded, deg) against time."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    path = Path(path)
    t = log.t_s
    fig = Figure(figsize=(11, 8), dpi=100, layout="constrained")
    grid = fig.add_gridspec(2, 2, width_ratios=(1.2, 1))
    ax_map = fig.add_subplot(grid[:, 0])
    ax_v = fig.add_subplot(grid[0, 1])
    ax_s = fig.add_subplot(grid[1, 1], sharex=ax_v)
    if track is not None:
        r = track.raster
        x0, x1, y0, y1 = r.extent_m() if callable(r.extent_m) else r.extent_m
        h = 0.5 * r.m_per_px  # extent_m is of pixel centres; imshow wants pixel edges
        ax_map.imshow(r.image, cmap="gray", vmin=0, vmax=255, extent=(x0 - h, x1 + h, y0 - h, y1 + h),
                      interpolation="nearest")
    if len(t):
        x, y = log.x_m, log.y_m
        off = log.off_track
        ax_map.plot(x, y, color="tab:green", lw=1.2, label="path")
        if off.any():
            ax_map.plot(np.where(off, x, np.nan), np.where(off, y, np.nan), color="tab:red",
                        lw=2, label="off track")
        ax_map.plot(x[:1], y[:1], "o", color="tab:blue", label="start")
        ax_map.plot(x[-1:], y[-1:], "s", color="tab:orange", label="end")
        ax_v.plot(t, log.speed_cmd_mps, color="tab:gray", lw=1, ls="--", label="commanded")
        ax_v.plot(t, log.speed_mps, color="tab:blue", lw=1.2, label="actual")
        ax_s.plot(t, np.degrees(log.steer_cmd_rad), color="tab:gray", lw=1, ls="--",
                  label="commanded")
        ax_s.plot(t, np.degrees(log.steer_rad), color="tab:red", lw=1.2, label="actual")
    ax_map.set_aspect("equal")
    ax_map.set_xlabel("x (m)")
    ax_map.set_ylabel("y (m)")
    ax_map.legend(loc="best", fontsize=8)
    ax_v.set_ylabel("speed (m/s)")
    ax_v.legend(loc="best", fontsize=8)
    ax_s.set_ylabel("steering (deg, + = left)")
    ax_s.set_xlabel("simulated time (s)")
    ax_s.legend(loc="best", fontsize=8)
    for ax in (ax_v, ax_s):
        ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title)
    tmp = path.with_name(path.stem + ".partial" + (path.suffix or ".png"))
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(tmp, format="png")
        tmp.replace(path)
    except (OSError, ValueError) as exc:
        tmp.unlink(missing_ok=True)
        raise SimError(f"{path}: cannot write plot ({exc})") from None
    return path

