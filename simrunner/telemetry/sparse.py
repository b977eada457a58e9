"""Merged topic logs: rows where each sensor fills only its own cells.

A log exported from several topics or sensors at their own rates (a PlotJuggler export, a
pandas merge of ROS topics, an MCU that writes a line per event) has one row per message,
and a row holds the cells of the sensor that sent it; the others are empty (or ``nan``).
:func:`merge_rows` turns such columns into one row per sample of the **leading sensor** -
the pose (``x_m, y_m, yaw_rad`` all in the row) when the log has one, else the speed sensor
(``speed_mps``) - which is how :func:`simrunner.workflows.gap` wants a measured log:

- the commands (``speed_cmd_mps``, ``steer_cmd_rad``, ``coast``) hold their last value until
  the next one (zero-order hold, as a command is in force until the next is sent): a row
  takes the last value stamped at or before its own stamp; rows before a command's first
  value are left out (the command is not known there);
- every other sensor (``speed_mps`` when the pose leads, ``yaw_rate_radps``) is interpolated
  linearly at the leading rows' stamps from its own samples, where the two samples around
  a stamp are at most :func:`gap_limit_s` apart (:data:`GAP_FACTOR` of that sensor's own
  long interval, its :data:`GAP_QUANTILE` quantile: the median for a regular sensor, more for
  one with irregular stamps, whose long intervals are not holes); a leading
  row outside that (a gap of the other sensor, before its first sample, after its last)
  is left out, so the log shows a time gap there rather than made-up values - except that a
  sensor starting late or ending early by more than :data:`MAX_OUTSIDE_S` and
  :data:`MAX_OUTSIDE_SHARE` of the log is left out instead of the log being cut to its span
  (a gyro that started late), and a note says so;
- a column without any value is absent; any other column with empty cells is dropped (the
  gap workflow reads none of them).

Rows must be in time order (``t_s`` never decreasing) and every row needs its time stamp;
``coast`` is checked (0 or 1) in the rows that logged it.
A log without empty cells is returned as it is.
"""
from __future__ import annotations

import numpy as np

POSE = ("x_m", "y_m", "yaw_rad")
HELD = ("speed_cmd_mps", "steer_cmd_rad", "coast")
INTERPOLATED = ("speed_mps", "yaw_rate_radps")
GAP_FACTOR = 5.0  # a step longer than this many of the stream's own long intervals is a hole
GAP_QUANTILE = 0.9  # the stream's own long interval: this quantile of its time steps
# a sensor starting late or ending early by more than both of these is left out (rather than
# the log cut to its span)
MAX_OUTSIDE_S = 2.0
MAX_OUTSIDE_SHARE = 0.1
FLAGS = ("coast",)


EMPTY_CELLS = ("", "nan", "-nan", "+nan", "na", "n/a", "null", "none")


def is_empty_cell(cell: str) -> bool:
    """A cell of a merged log that holds no value: empty, blanks, or one of
    :data:`EMPTY_CELLS` in any case (``nan`` of Python/pandas, ``-nan`` of C's printf, ``NA`` of R)."""
    return cell.strip().lower() in EMPTY_CELLS


class SparseError(ValueError):
    """A merged log that cannot be made into rows: ``row`` (0-based) and what was expected."""

    def __init__(self, row: int, message: str):
        super().__init__(message)
        self.row, self.message = row, message


def gap_limit_s(steps_s: np.ndarray) -> float:
    """The longest time step of a stream (a sensor's samples, a log's rows) that is not a
    hole: :data:`GAP_FACTOR` times the :data:`GAP_QUANTILE` quantile of its positive steps.

    For a regular stream that quantile is its median step (every step is one); a stream
    with irregular stamps - a controller or logger acting at irregular times, a sensor with
    jitter - has long intervals as part of its normal rhythm, and only a step well beyond
    them means samples were lost. A stream that loses more than a tenth of its steps to
    holes sets its own normal that high, so only holes 5 times longer are found; such a log
    is mostly holes. 0 when no step is positive."""
    steps_s = np.asarray(steps_s, dtype=float)
    positive = steps_s[steps_s > 0]
    return GAP_FACTOR * float(np.quantile(positive, GAP_QUANTILE)) if positive.size else 0.0


def _interpolate(t: np.ndarray, own: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``own`` (NaN where the sensor has no sample) at the stamps ``at``; NaN where the own
    samples around a stamp are more than :func:`gap_limit_s` apart, or outside them."""
    have = np.isfinite(own)
    ts, vs = t[have], own[have]
    out = np.full(len(at), np.nan)
    if ts.size < 2:
        return out
    steps = np.diff(ts)
    limit = gap_limit_s(steps)
    k = np.searchsorted(ts, at, side="right")  # ts[k - 1] <= at < ts[k]
    exact = (k >= 1) & (ts[np.clip(k - 1, 0, ts.size - 1)] == at)
    inside = (k >= 1) & (k < ts.size)
    lo, hi = np.clip(k - 1, 0, ts.size - 1), np.clip(k, 0, ts.size - 1)
    ok = inside & (ts[hi] - ts[lo] <= limit) & (ts[hi] > ts[lo])
    w = np.where(ok, (at - ts[lo]) / np.where(ok, ts[hi] - ts[lo], 1.0), 0.0)
    out[ok] = (vs[lo] + w * (vs[hi] - vs[lo]))[ok]
    out[exact] = vs[np.clip(k - 1, 0, ts.size - 1)][exact]
    return out


def _held(t: np.ndarray, own: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``own`` (NaN where the column logged nothing) held: at each stamp of ``at`` the last
    value stamped at or before it; NaN before its first value."""
    have = np.flatnonzero(np.isfinite(own))
    last = np.searchsorted(t[have], at, side="right") - 1
    return np.where(last >= 0, own[have[np.clip(last, 0, None)]], np.nan)


def merge_rows(values: dict) -> tuple[dict, np.ndarray, list[str]]:
    """``(columns, rows kept, notes)`` of a merged log's columns (module docstring): numeric
    columns are float arrays with NaN for an empty cell, text columns tuples. ``rows kept``
    are the indices of the input rows the output's rows come from; ``notes`` say what was
    left out (a sensor dropped). Raises :class:`SparseError`."""
    numeric = {k: v for k, v in values.items() if not isinstance(v, tuple)}
    n = len(values["t_s"])
    if all(np.isfinite(v).all() for v in numeric.values()):
        return values, np.arange(n), []
    t = np.asarray(values["t_s"], dtype=float)
    missing = np.flatnonzero(~np.isfinite(t))
    if missing.size:
        raise SparseError(int(missing[0]), "column 't_s': expected a time stamp in every row of a merged log")
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise SparseError(i, f"column 't_s': expected the rows of a merged log in time order (got {t[i]!r} "
                             f"after {t[i - 1]!r})")
    for name in FLAGS:  # checked where they were logged (a held value is copied to other rows)
        v = numeric.get(name)
        bad = np.flatnonzero(np.isfinite(v) & (v != 0.0) & (v != 1.0)) if v is not None else []
        if len(bad):
            raise SparseError(int(bad[0]), f"column {name!r}: expected 0 or 1 (got {v[bad[0]]!r})")
    present = {k for k, v in numeric.items() if np.isfinite(v).any()}
    if all(c in present for c in POSE):
        lead, leader = np.all([np.isfinite(numeric[c]) for c in POSE], axis=0), "the pose (x_m, y_m, yaw_rad)"
        if not lead.any():
            raise SparseError(int(np.flatnonzero(np.isfinite(numeric["x_m"]))[0]),
                              "columns x_m, y_m, yaw_rad never share a row: expected a merged log's pose in "
                              "one row per pose sample")
    elif "speed_mps" in present:
        lead, leader = np.isfinite(numeric["speed_mps"]), "the speed sensor (speed_mps)"
    else:  # empty cells and nothing to lead
        name = next(k for k, v in numeric.items() if not np.isfinite(v).all())
        row = int(np.flatnonzero(~np.isfinite(numeric[name]))[0])
        raise SparseError(row, f"column {name!r}: an empty cell (a merged log): expected a pose (x_m, y_m, "
                               f"yaw_rad) or a speed sensor (speed_mps) with values, whose rows the log is read at")
    rows = np.flatnonzero(lead)
    keep = np.ones(rows.size, dtype=bool)
    notes: list[str] = []
    out: dict = {"t_s": t[rows]}
    for name in HELD:  # first: a sensor's coverage is judged on the rows with commands
        v = numeric.get(name)
        if name not in present or np.isfinite(v[rows]).all():
            continue
        out[name] = _held(t, v, t[rows])
        keep &= np.isfinite(out[name])
    if not keep.any():
        raise SparseError(int(rows[-1]), f"no sample of {leader} comes after the first command: expected "
                                         f"commands (speed_cmd_mps, steer_cmd_rad) from the start of the log")
    for name, v in numeric.items():
        if name == "t_s" or name not in present or name in out:
            continue
        if np.isfinite(v[rows]).all():
            out[name] = v[rows]  # a leading column, or one with a value in every leading row
        elif name in INTERPOLATED:
            own = t[np.isfinite(v)]
            span = t[rows][keep]  # the rows with commands
            outside_s = max(own[0] - span[0], 0.0) + max(span[-1] - own[-1], 0.0)
            if outside_s > max(MAX_OUTSIDE_S, MAX_OUTSIDE_SHARE * (span[-1] - span[0])):
                notes.append(f"column {name!r} covers only t = {own[0]:.3f}..{own[-1]:.3f} s of the "
                             f"{span[0]:.3f}..{span[-1]:.3f} s of {leader}: left out (keeping it would cut "
                             f"{outside_s:.3g} s off the log)")
                continue
            out[name] = _interpolate(t, v, t[rows])
            keep &= np.isfinite(out[name])  # its holes become time gaps
        # other columns with empty cells: not read by the gap workflow, dropped
    for name, v in values.items():
        if isinstance(v, tuple):
            out[name] = tuple(v[i] for i in rows)
    kept = rows[keep]
    idx = np.flatnonzero(keep)
    return {k: (tuple(v[i] for i in idx) if isinstance(v, tuple) else v[keep]) for k, v in out.items()}, kept, notes


def command_steps(values: dict) -> dict[str, np.ndarray] | None:
    """The commands of a merged log (the raw columns :func:`merge_rows` reads, after it
    accepted them) at their own stamps: ``{"t_s", "speed_cmd_mps", "steer_cmd_rad"[, "coast"]}``,
    one entry per row that logged a command column, every command column held at its last
    value (zero-order hold, as :func:`merge_rows` holds them), from the first stamp where all
    are known; of several rows with one stamp the last counts. None for a log without
    empty cells (its rows are its commands) or without both command columns."""
    numeric = {k: np.asarray(v, dtype=float) for k, v in values.items() if not isinstance(v, tuple)}
    if all(np.isfinite(v).all() for v in numeric.values()):
        return None
    names = [n for n in HELD if n in numeric and np.isfinite(numeric[n]).any()]
    if "speed_cmd_mps" not in names or "steer_cmd_rad" not in names:
        return None
    t = numeric["t_s"]
    rows = np.flatnonzero(np.any([np.isfinite(numeric[n]) for n in names], axis=0))
    out = {"t_s": t[rows]}
    for n in names:
        out[n] = _held(t, numeric[n], t[rows])
    keep = np.all([np.isfinite(out[n]) for n in names], axis=0)
    keep &= np.append(np.diff(out["t_s"]) > 0.0, True)  # one stamp, several rows: the last
    out = {k: v[keep] for k, v in out.items()}
    if "coast" in out:
        out["coast"] = out["coast"] == 1.0
    return out


__all__ = ["merge_rows", "command_steps", "is_empty_cell", "SparseError", "EMPTY_CELLS", "GAP_FACTOR", "GAP_QUANTILE", "gap_limit_s",
           "MAX_OUTSIDE_S",
           "MAX_OUTSIDE_SHARE"]
