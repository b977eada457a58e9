"""Measured logs: read and check the telemetry CSV, and derive smoothed states from it.

The schema is the one ``simrunner drive`` writes (extra columns are ignored):

    t          s     sample time, strictly increasing
    x, y       m     rear-axle midpoint in the world frame
    yaw        rad   heading, counter-clockwise from +x (any wrapping)
    speed      m/s   signed speed along the car's x axis
    speed_cmd  m/s   commanded speed (physical units)
    steer_cmd  rad   commanded bicycle-equivalent steering angle, positive = left

Optional column (as written by ``simrunner excite``'s ``run_plan``):

    coast      0/1   drive off, rear wheels rolling freely (absent: never coasting)

Commands are taken as held from their sample to the next one (zero-order hold), as
``simrunner.workflows.excite.run_plan`` logs them: the state at ``t_k`` and the command set at ``t_k``.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simrunner.workflows.gap import LogError

COLUMNS = ("t", "x", "y", "yaw", "speed", "speed_cmd", "steer_cmd")
OPTIONAL = ("coast",)
MIN_ROWS = 50
MIN_DURATION_S = 6.0  # three 2-s replay windows: two to fit, one to hold out
SMOOTH_S = 0.15  # Savitzky-Golay window for states and their derivatives
MIN_SPEED_FOR_STEER_MPS = 0.15  # below this the steer estimate falls back to the command


@dataclass(frozen=True)
class MeasuredLog:
    """One log; every array has shape (N,) and float64 values."""

    t_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    yaw_rad: np.ndarray
    speed_mps: np.ndarray
    speed_cmd_mps: np.ndarray
    steer_cmd_rad: np.ndarray
    source: str = "<log>"
    coast: np.ndarray | None = None  # (N,) bool, or None: never coasting

    def __len__(self) -> int:
        return int(self.t_s.size)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])

    def as_columns(self) -> dict[str, np.ndarray]:
        """The schema's columns by their CSV names."""
        cols = {"t": self.t_s, "x": self.x_m, "y": self.y_m, "yaw": self.yaw_rad,
                "speed": self.speed_mps, "speed_cmd": self.speed_cmd_mps, "steer_cmd": self.steer_cmd_rad}
        if self.coast is not None:
            cols["coast"] = self.coast.astype(float)
        return cols

    def coasting(self) -> np.ndarray:
        """(N,) bool: drive off at each sample."""
        return np.zeros(len(self), dtype=bool) if self.coast is None else self.coast

    def subset(self, stop: int) -> "MeasuredLog":
        """The first ``stop`` samples (checked like any log)."""
        return log_from_columns({k: v[:stop] for k, v in self.as_columns().items()}, self.source)


def log_from_columns(columns: dict[str, np.ndarray], source: str = "<log>") -> MeasuredLog:
    """Build and check a log from arrays keyed by the CSV column names (extra keys ignored).

    Line numbers in errors count the header as line 1, as in the CSV file.
    """
    missing = [c for c in COLUMNS if c not in columns]
    if missing:
        raise LogError(source, 1, f"expected columns {', '.join(COLUMNS)} (missing: {', '.join(missing)})")
    names = COLUMNS + tuple(c for c in OPTIONAL if c in columns)
    arrays = {c: np.asarray(columns[c], dtype=float).reshape(-1) for c in names}
    n = arrays["t"].size
    for c, a in arrays.items():
        if a.size != n:
            raise LogError(source, 1, f"expected every column to have {n} values ({c!r} has {a.size})")
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise LogError(source, int(bad[0]) + 2, f"column {c!r}: expected a finite number")
    coast = None
    if "coast" in arrays:
        bad = np.flatnonzero((arrays["coast"] != 0.0) & (arrays["coast"] != 1.0))
        if bad.size:
            raise LogError(source, int(bad[0]) + 2, "column 'coast': expected 0 or 1")
        coast = arrays["coast"] == 1.0
    _check_time(arrays["t"], source)
    return MeasuredLog(arrays["t"], arrays["x"], arrays["y"], arrays["yaw"], arrays["speed"],
                       arrays["speed_cmd"], arrays["steer_cmd"], source, coast)


def _check_time(t: np.ndarray, source: str) -> None:
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if bad.size:
        i = int(bad[0]) + 1
        raise LogError(source, i + 2, f"column 't': expected strictly increasing time (got {t[i]!r} "
                       f"after {t[i - 1]!r})")
    if t.size < MIN_ROWS or t[-1] - t[0] < MIN_DURATION_S:
        span = float(t[-1] - t[0]) if t.size else 0.0
        raise LogError(source, t.size + 1, f"expected at least {MIN_ROWS} rows and {MIN_DURATION_S:g} s of data "
                       f"(got {t.size} rows, {span:.3g} s)")


def read_log(path: str | Path) -> MeasuredLog:
    """Read and check a telemetry CSV; raise :class:`LogError` (``path:line: ...``) if bad."""
    path = Path(path)
    try:
        handle = path.open(newline="")
    except OSError as exc:
        raise LogError(str(path), 0, f"expected a readable CSV file ({exc.strerror})") from None
    with handle:
        try:
            reader = csv.reader(handle)
            header = next(reader, None)
            if header is None:
                raise LogError(str(path), 1, f"expected a header line with columns {', '.join(COLUMNS)}")
            names = [h.strip() for h in header]
            missing = [c for c in COLUMNS if c not in names]
            if missing:
                raise LogError(str(path), 1, f"expected columns {', '.join(COLUMNS)} "
                               f"(missing: {', '.join(missing)})")
            wanted = COLUMNS + tuple(c for c in OPTIONAL if c in names)
            index = [names.index(c) for c in wanted]
            rows: list[list[float]] = []
            for row in reader:
                line = reader.line_num
                if not row or all(not cell.strip() for cell in row):
                    continue
                if len(row) < len(names):
                    raise LogError(str(path), line, f"expected {len(names)} cells (got {len(row)})")
                values = []
                for c, i in zip(wanted, index):
                    try:
                        v = float(row[i])
                    except ValueError:
                        raise LogError(str(path), line, f"column {c!r}: expected a number "
                                       f"(got {row[i]!r})") from None
                    if not math.isfinite(v):
                        raise LogError(str(path), line, f"column {c!r}: expected a finite number "
                                       f"(got {row[i]!r})")
                    values.append(v)
                rows.append(values)
        except UnicodeDecodeError:
            raise LogError(str(path), 1, "expected a text (CSV) file") from None
        except csv.Error as exc:
            raise LogError(str(path), reader.line_num, f"expected valid CSV ({exc})") from None
    data = np.array(rows, dtype=float).reshape(-1, len(wanted))
    return log_from_columns({c: data[:, k] for k, c in enumerate(wanted)}, str(path))


def write_log(log: MeasuredLog, path: str | Path) -> None:
    """Write the schema's columns (full float precision) atomically."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    cols = log.as_columns()
    data = np.column_stack(list(cols.values()))
    with tmp.open("w", newline="") as f:
        f.write(",".join(cols) + "\n")
        for row in data:
            f.write(",".join(repr(float(v)) for v in row) + "\n")
    tmp.replace(path)


@dataclass(frozen=True)
class Derived:
    """Smoothed states of a log (Savitzky-Golay, ``SMOOTH_S`` window), all shape (N,).

    ``yaw_rad`` is unwrapped; ``yaw_rate_radps`` and ``accel_mps2`` are derivatives of the
    smoothed yaw and speed; ``steer_rad`` is the bicycle-equivalent steer that explains the
    yaw rate, ``atan(L * r / v)``, or the command where ``|v|`` is small.
    """

    x_m: np.ndarray
    y_m: np.ndarray
    yaw_rad: np.ndarray
    speed_mps: np.ndarray
    yaw_rate_radps: np.ndarray
    accel_mps2: np.ndarray
    steer_rad: np.ndarray


def sample_dt_s(log: MeasuredLog) -> float:
    """Median sample interval."""
    return float(np.median(np.diff(log.t_s)))


def derive(log: MeasuredLog, wheelbase_m: float, steer_limit_rad: float = math.inf) -> Derived:
    """Smoothed states and derivatives; see :class:`Derived`."""
    from scipy.signal import savgol_filter  # here, not at import: `simrunner gap --help` stays quick
    dt = sample_dt_s(log)
    win = max(5, int(round(SMOOTH_S / dt)) | 1)
    n = len(log)
    win = min(win, n if n % 2 else n - 1)
    t = log.t_s
    # Savitzky-Golay assumes a uniform grid: resample, filter, and sample back.
    grid = np.linspace(t[0], t[-1], len(log))
    step = grid[1] - grid[0]

    def smooth(v: np.ndarray, deriv: int = 0) -> np.ndarray:
        g = np.interp(grid, t, v)
        s = savgol_filter(g, win, 2, deriv=deriv, delta=step, mode="interp")
        return np.interp(t, grid, s)

    yaw_u = np.unwrap(log.yaw_rad)
    speed = smooth(log.speed_mps)
    yaw_rate = smooth(yaw_u, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        steer = np.arctan(wheelbase_m * yaw_rate / speed)
    slow = np.abs(speed) < MIN_SPEED_FOR_STEER_MPS
    steer = np.where(slow, log.steer_cmd_rad, steer)
    steer = np.clip(steer, -steer_limit_rad, steer_limit_rad)
    return Derived(smooth(log.x_m), smooth(log.y_m), smooth(yaw_u), speed, yaw_rate,
                   smooth(log.speed_mps, 1), steer)
