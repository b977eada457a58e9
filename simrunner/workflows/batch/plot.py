"""The batch summary plot (``summary.png``): three panels over the result rows.

1. Best lap time (s) by track, one marker series per parameter combination (runs without a
   completed lap are drawn as crosses on the bottom axis; when no run completed one, the
   panel says so, with no time scale).
2. Outcomes per parameter combination (stacked counts).
3. Where runs leave the track: the fraction of the lap (distance along the centreline from
   the start) at which ``off_track`` runs left the road, by track, the parameter
   combinations side by side as in panel 1.

The legends sit beside their panels.
"""
from __future__ import annotations

from pathlib import Path


def _combo(row: dict, names: tuple[str, ...]) -> str:
    return ", ".join(f"{n}={row[n]}" for n in names) or "all runs"


def plot_summary(rows: list[dict], param_names: tuple[str, ...], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tracks = list(dict.fromkeys(r["track"] for r in rows))
    tx = {t: i for i, t in enumerate(tracks)}
    combos = list(dict.fromkeys(_combo(r, param_names) for r in rows))
    outcomes = list(dict.fromkeys(r["outcome"] for r in rows))
    colours = plt.get_cmap("tab10")
    n = len(combos)
    fig, axes = plt.subplots(3, 1, figsize=(max(8.0, min(24.0, 0.35 * len(tracks) + 6)), 12),
                             constrained_layout=True)
    dxs = [(k - (n - 1) / 2) * min(0.8 / max(n, 1), 0.15) for k in range(n)]  # combos side by side
    ax = axes[0]
    for k, combo in enumerate(combos):
        sel = [r for r in rows if _combo(r, param_names) == combo]
        dx = dxs[k]
        done = [r for r in sel if r["best_lap_s"] is not None]
        ax.scatter([tx[r["track"]] + dx for r in done], [r["best_lap_s"] for r in done],
                   s=18, color=colours(k % 10), label=combo)
        failed = [r for r in sel if r["best_lap_s"] is None]
        if failed:
            ax.scatter([tx[r["track"]] + dx for r in failed], [0.0] * len(failed), marker="x",
                       s=22, color=colours(k % 10))
    ax.set_ylabel("best lap time (s); x = no lap")
    if all(r["best_lap_s"] is None for r in rows):  # no time scale to show: the crosses alone
        ax.set_yticks([])
        ax.text(0.5, 0.75, "no run completed a lap", ha="center", va="center", transform=ax.transAxes,
                fontsize=9, color="0.4")
    ax.set_title("Lap time by track and parameters")
    _track_axis(ax, tracks)
    if n <= 12:
        _legend_beside(ax)

    ax = axes[1]
    bottom = [0] * n
    for j, outcome in enumerate(outcomes):
        counts = [sum(1 for r in rows if r["outcome"] == outcome and _combo(r, param_names) == c)
                  for c in combos]
        ax.bar(range(n), counts, bottom=bottom, label=outcome, color=plt.get_cmap("Set2")(j % 8))
        bottom = [b + c for b, c in zip(bottom, counts)]
    ax.set_xticks(range(n), combos, rotation=30 if n > 4 else 0, ha="right" if n > 4 else "center",
                  fontsize=7)
    ax.set_ylabel("runs")
    ax.set_title("Outcomes by parameters")
    _legend_beside(ax)

    ax = axes[2]
    off = [r for r in rows if r["off_progress_frac"] is not None]
    for k, combo in enumerate(combos):
        sel = [r for r in off if _combo(r, param_names) == combo]
        if sel:
            ax.scatter([tx[r["track"]] + dxs[k] for r in sel], [r["off_progress_frac"] for r in sel], s=18,
                       color=colours(k % 10), label=combo)
    ax.set_ylim(-0.02, 1.02)
    ax.set_ylabel("fraction of the lap")
    ax.set_title(f"Where runs leave the track ({len(off)} of {len(rows)} runs)")
    _track_axis(ax, tracks)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _legend_beside(ax) -> None:
    """The panel's legend to its right, outside: inside it hid markers or bars."""
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)


def _track_axis(ax, tracks: list[str]) -> None:
    ax.set_xlim(-0.6, len(tracks) - 0.4)
    if len(tracks) <= 30:
        ax.set_xticks(range(len(tracks)), [Path(t).stem if "/" in t else t for t in tracks],
                      rotation=45 if len(tracks) > 5 else 0, ha="right" if len(tracks) > 5 else "center",
                      fontsize=7)
    ax.set_xlabel("track")
