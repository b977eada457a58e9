"""Run plot (thesis Fig. 3.8) of any run log -> PNG: the path (over the track when it is
known), speed, steering and yaw rate against time, each actual and commanded.

Works on whatever columns a log has (a simulated run's telemetry, or a real car's log read
through a column mapping): a panel whose columns are missing says so. Lap completions
(where ``lap`` steps up) are numbered markers on the path and dotted lines in the time
panels; the first off-track row is a red cross on the path and a red line in the panels.

matplotlib's Agg canvas (no pyplot, no display, no global state); written atomically.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from simrunner.errors import SimError
from simrunner.telemetry.log import RunLog
from vehicle.userfiles import write_atomic


MAX_LAP_LABELS = 12  # laps after these get a marker but no label


def lap_rows(log: RunLog) -> np.ndarray:
    """Row indices where a lap was completed (the ``lap`` count steps up); empty without a
    ``lap`` column."""
    if log.lap is None or len(log) < 2:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(np.diff(log.lap) > 0) + 1


def off_track_row(log: RunLog) -> int | None:
    """The first row flagged off track (None: never, or no ``off_track`` column)."""
    if log.off_track is None or not log.off_track.any():
        return None
    return int(np.argmax(log.off_track))


def _track_background(ax, track) -> None:
    r = track.raster
    x0, x1, y0, y1 = r.extent_m() if callable(r.extent_m) else r.extent_m
    h = 0.5 * r.m_per_px  # extent_m is of pixel centres; imshow wants pixel edges
    ax.imshow(r.image, cmap="gray", vmin=0, vmax=255, extent=(x0 - h, x1 + h, y0 - h, y1 + h),
              interpolation="nearest")


def _lap_label(log: RunLog, laps: np.ndarray, n: int, lap_times_s) -> str:
    """Lap ``n``'s label on the path: its judged time when the run's lap times are known (the
    gate crossing, interpolated between frames), else the log's time of the row it was counted at
    (the frame after the crossing)."""
    if lap_times_s is not None and len(lap_times_s) == laps.size:
        return f"lap {n}: {lap_times_s[n - 1]:.2f} s"
    return f"lap {n} done at {log.t_s[laps[n - 1]]:.2f} s"


def _map_panel(ax, log: RunLog, laps: np.ndarray, off: int | None, lap_times_s=None) -> None:
    if log.x_m is None or log.y_m is None or not len(log):
        ax.text(0.5, 0.5, "no position (x_m, y_m) in this log", ha="center", va="center",
                transform=ax.transAxes)
        return
    x, y = log.x_m, log.y_m
    ax.plot(x, y, color="tab:green", lw=1.2, label="path")
    if log.off_track is not None and log.off_track.any():
        ax.plot(np.where(log.off_track, x, np.nan), np.where(log.off_track, y, np.nan),
                color="tab:red", lw=2, label="off track")
    ax.plot(x[:1], y[:1], "o", color="tab:blue", ms=7, label="start")
    ax.plot(x[-1:], y[-1:], "s", color="tab:orange", ms=7, label="end")
    if laps.size:
        ax.plot(x[laps], y[laps], "D", color="gold", mec="black", ms=8, label="lap completed")
        for n, i in enumerate(laps[:MAX_LAP_LABELS], 1):  # laps end near one line: stagger
            ax.annotate(_lap_label(log, laps, n, lap_times_s), (x[i], y[i]), textcoords="offset points",
                        xytext=(10, 6 + 15 * (n - 1)), fontsize=8, arrowprops={"arrowstyle": "-", "lw": 0.5}, bbox={"boxstyle": "round", "fc": "lightyellow",
                                                         "alpha": 0.85})
    if off is not None:
        ax.plot(x[off], y[off], "X", color="red", mec="black", ms=14, label="left the track")
        ax.annotate(f"off track\n{log.t_s[off]:.2f} s", (x[off], y[off]), textcoords="offset points",
                    xytext=(10, -24), fontsize=9, color="darkred", fontweight="bold",
                    bbox={"boxstyle": "round", "fc": "white", "ec": "red", "alpha": 0.9})
    # above the map, not on it: "best" avoids the lines but not the lap and off-track labels
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=5, fontsize=8, frameon=False)


def _time_panel(ax, t, actual, commanded, unit: str, scale: float = 1.0) -> None:
    drawn = False
    if commanded is not None:
        ax.plot(t, commanded * scale, color="tab:gray", lw=1, ls="--", label="commanded")
        drawn = True
    if actual is not None:
        ax.plot(t, actual * scale, color="tab:blue", lw=1.2, label="actual")
        drawn = True
    ax.set_ylabel(unit)
    if drawn:
        ax.legend(loc="best", fontsize=8)
    else:
        ax.text(0.5, 0.5, "not in this log", ha="center", va="center", transform=ax.transAxes)
    ax.grid(True, alpha=0.3)


def plot_run(log: RunLog, track, path: str | Path, *, title: str = "",
             lap_times_s: list[float] | None = None) -> Path:
    """Write the plot of ``log`` to ``path`` (PNG); ``track``: a ``SimTrack`` drawn under the
    path, or None; ``lap_times_s``: the run's judged lap times (a drive's; the laps on the path
    are labelled with them, as in the title). Raises :class:`SimError` when the file cannot be
    written."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    path = Path(path)
    t = log.t_s
    laps, off = lap_rows(log), off_track_row(log)
    fig = Figure(figsize=(12, 8), dpi=100, layout="constrained")
    grid = fig.add_gridspec(3, 2, width_ratios=(1.2, 1))
    ax_map = fig.add_subplot(grid[:, 0])
    ax_v = fig.add_subplot(grid[0, 1])
    ax_s = fig.add_subplot(grid[1, 1], sharex=ax_v)
    ax_w = fig.add_subplot(grid[2, 1], sharex=ax_v)
    if track is not None:
        _track_background(ax_map, track)
    _map_panel(ax_map, log, laps, off, lap_times_s)
    ax_map.set_aspect("equal")
    ax_map.set_xlabel("x (m)")
    ax_map.set_ylabel("y (m)")
    _time_panel(ax_v, t, log.speed_mps, log.speed_cmd_mps, "speed (m/s)")
    _time_panel(ax_s, t, log.steer_rad, log.steer_cmd_rad, "steering (deg, + = left)",
                float(np.degrees(1.0)))
    _time_panel(ax_w, t, log.yaw_rate_radps, log.yaw_rate_cmd_radps, "yaw rate (deg/s, + = left)",
                float(np.degrees(1.0)))
    ax_w.set_xlabel("time (s)")
    for ax in (ax_v, ax_s, ax_w):
        for n, i in enumerate(laps, 1):
            ax.axvline(t[i], color="goldenrod", ls=":", lw=1.2)
            if ax is ax_v and n <= MAX_LAP_LABELS:  # left of its line near the end: not cut
                late = t[i] > t[0] + 0.9 * (t[-1] - t[0])
                ax.annotate(f"lap {n}", (t[i], 1.0), xycoords=("data", "axes fraction"),
                            xytext=(-2 if late else 2, -10), textcoords="offset points", fontsize=7,
                            ha="right" if late else "left")
        if off is not None:
            ax.axvline(t[off], color="red", lw=1.5)
    if off is not None:
        ax_v.annotate("off track", (t[off], 0.0), xycoords=("data", "axes fraction"),
                      xytext=(3, 4), textcoords="offset points", fontsize=8, color="darkred")
    if title:
        fig.suptitle(title)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, lambda tmp: fig.savefig(tmp, format="png"))
    except (OSError, ValueError) as exc:
        raise SimError(f"{path}: cannot write plot ({exc})") from None
    return path


def log_title(log: RunLog) -> str:
    """A title for a log read from a file: its name, rows, duration, laps, off track."""
    parts = [f"{Path(log.source).name}: {len(log)} rows, {log.duration_s:.1f} s"]
    laps = lap_rows(log)
    if log.lap is not None:
        parts.append(f"{laps.size} lap(s)" + (f" completed at {', '.join(f'{log.t_s[i]:.2f}' for i in laps)} s"
                                             if laps.size else ""))
    off = off_track_row(log)
    if off is not None:
        parts.append(f"off track at {log.t_s[off]:.2f} s")
    return ", ".join(parts)
