"""Figures of the gap report (matplotlib, Agg backend, no display needed)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from simrunner.workflows.gap.glitches import has_pose  # noqa: E402
from simrunner.workflows.gap.replay import window_mask  # noqa: E402

_REGIME_ORDER = ("all", "accelerating", "braking", "coasting", "steady", "straight", "left", "right", "reversing",
                 "high_lat_accel")


def _shade_held(ax, result) -> None:
    t = result.log.t_s
    for k, w in enumerate(result.held_windows):
        ax.axvspan(t[w.start], t[w.stop - 1], color="0.9", zorder=0, label="held out" if k == 0 else None)


def _no_data(ax, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, fontsize=9, color="0.4")
    ax.set_xticks([])
    ax.set_yticks([])


def plot_before_after(result, path: str | Path) -> None:
    """2x2 figure: path in xy, speed, yaw rate and position error over time, measured vs
    nominal ("before") vs fitted ("after"); held-out windows shaded."""
    log, d = result.log, result.derived
    p0, p1 = result.pred_before, result.pred_after
    t = log.t_s
    pose = has_pose(log)
    fig, axes = plt.subplots(2, 2, figsize=(12, 8), dpi=90)
    ax = axes[0, 0]
    if pose:
        ax.plot(log.x_m, log.y_m, color="k", lw=1.0, label="measured")
        ax.plot(p0.x_m, p0.y_m, color="tab:red", lw=0.9, label="nominal")
        ax.plot(p1.x_m, p1.y_m, color="tab:blue", lw=0.9, ls="--", label=f"+ {result.effect}")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title("path (each window restarts from the measured state)")
    else:
        _no_data(ax, "path: the log has no pose (x_m, y_m, yaw_rad)")
    speed = log.speed_mps if log.speed_mps is not None else d.speed_mps
    yaw_rate = log.yaw_rate_radps if log.yaw_rate_radps is not None else d.yaw_rate_radps
    for ax, meas, a, b, label in (
            (axes[0, 1], speed, p0.speed_mps, p1.speed_mps, "speed (m/s)"),
            (axes[1, 0], yaw_rate, p0.yaw_rate_radps, p1.yaw_rate_radps, "yaw rate (rad/s)")):
        if not np.isfinite(meas).any():
            _no_data(ax, f"{label}: not measured")
            continue
        _shade_held(ax, result)
        ax.plot(t, meas, color="k", lw=0.8, label="measured")
        ax.plot(t, a, color="tab:red", lw=0.8, label="nominal")
        ax.plot(t, b, color="tab:blue", lw=0.8, ls="--", label=f"+ {result.effect}")
        ax.set_xlabel("t (s)")
        ax.set_ylabel(label)
    ax = axes[1, 1]
    if pose:
        _shade_held(ax, result)
        e0 = np.hypot(p0.x_m - log.x_m, p0.y_m - log.y_m)
        e1 = np.hypot(p1.x_m - log.x_m, p1.y_m - log.y_m)
        ax.plot(t, e0, color="tab:red", lw=0.8, label="nominal")
        ax.plot(t, e1, color="tab:blue", lw=0.8, ls="--", label=f"+ {result.effect}")
        ax.set_xlabel("t (s)")
        ax.set_ylabel("position error (m)")
    else:
        _no_data(ax, "position error: the log has no pose")
    held = window_mask(len(log), result.held_windows)
    shown = [(s, label) for s, label in (("position_m", "position"), ("speed_mps", "speed"),
                                         ("yaw_rate_radps", "yaw rate"))
             if np.isfinite(result.rmse_before.get(s, np.nan))]
    ax.set_title("held-out RMSE before -> after:\n" + _lines([
        f"{label} {result.rmse_before[s]:.3g} -> {result.rmse_after.get(s, np.nan):.3g}" for s, label in shown], 70)
        if held.any() and shown else "", fontsize=9)
    head = f"{Path(log.source).name}: effects = {result.effect}"
    params = [f"{k} = {v:.4g}" for k, v in result.parameters.items()]
    fig.suptitle(_lines([f"{head} ({params[0]}", *params[1:-1], f"{params[-1]})"] if len(params) > 1 else
                        [f"{head} ({params[0]})"] if params else [head], 120))
    _legend_below(fig, axes.ravel(), fontsize=9)
    fig.savefig(path)
    plt.close(fig)


def _legend_below(fig, axes, fontsize: float) -> None:
    """One legend of the panels' labelled artists (each label once), in a band below the
    panels: inside a panel it hid curves or bars wherever it sat. Lays the figure out."""
    entries: dict[str, object] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            entries.setdefault(label, handle)
    if not entries:
        fig.tight_layout()
        return
    legend = fig.legend(list(entries.values()), list(entries), loc="lower center", ncol=len(entries),
                        fontsize=fontsize, frameon=False)
    fig.canvas.draw()  # the legend's height, to keep its band free
    band = legend.get_window_extent().height / fig.bbox.height
    fig.tight_layout(rect=(0.0, band + 0.01, 1.0, 1.0))


def _lines(items: list[str], width: int) -> str:
    """``items`` joined by ", ", a new line before one that would pass ``width`` characters."""
    lines = [""]
    for item in items:
        if lines[-1] and len(lines[-1]) + 2 + len(item) > width:
            lines[-1] += ","
            lines.append("")
        lines[-1] += (", " if lines[-1] else "") + item
    return "\n".join(lines)


def plot_regimes(result, path: str | Path) -> None:
    """One panel per signal: RMSE per regime before/after (bars) and bias (markers)."""
    signals = ("position_m", "cross_m", "yaw_rad", "speed_mps", "yaw_rate_radps", "along_m")
    fig, axes = plt.subplots(2, 3, figsize=(14, 7), dpi=90)
    legend_ax = None  # the first panel with data (a log without a pose has no position panel)
    for ax, sig in zip(axes.ravel(), signals):
        rows0 = {r["regime"]: r for r in result.stats_before if r["signal"] == sig}
        rows1 = {r["regime"]: r for r in result.stats_after if r["signal"] == sig}
        regs = [g for g in _REGIME_ORDER if rows0.get(g, {}).get("count") and g in rows1]
        if not regs:
            _no_data(ax, f"{sig}: not measured")
            continue
        x = np.arange(len(regs))
        ax.bar(x - 0.2, [rows0[g]["rmse"] for g in regs], 0.4, color="tab:red", label="RMSE nominal")
        ax.bar(x + 0.2, [rows1[g]["rmse"] for g in regs], 0.4, color="tab:blue", label="RMSE fitted")
        ax.plot(x - 0.2, [rows0[g]["bias"] for g in regs], "kv", ms=5, label="bias nominal")
        ax.plot(x + 0.2, [rows1[g]["bias"] for g in regs], "k^", ms=5, label="bias fitted")
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.set_xticks(x, regs, rotation=35, fontsize=8)
        ax.set_title(sig)
        legend_ax = legend_ax or ax
    fig.suptitle(f"residuals by regime (all windows): nominal vs + {result.effect}")
    _legend_below(fig, [legend_ax] if legend_ax is not None else [], fontsize=8)
    fig.savefig(path)
    plt.close(fig)
