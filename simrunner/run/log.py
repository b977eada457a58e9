"""Telemetry of a run: one row per camera frame, written as CSV (schema: docs/telemetry.md).

Rows are kept in memory during the run (a tuple per frame; a 60 s run at 50 fps is 3000
rows) and written once at the end, atomically (``PATH.tmp`` then rename), also when the
controller crashed. Number formats are fixed, so the same run gives the same bytes.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from simrunner.errors import SimError

# (column, printf format); units: docs/telemetry.md
SCHEMA: tuple[tuple[str, str], ...] = (
    ("frame", "%d"),          # camera frame index, 0 = initial state
    ("t", "%.6f"),            # simulated time, s
    ("x", "%.6f"),            # rear-axle midpoint, world, m
    ("y", "%.6f"),
    ("yaw", "%.6f"),          # heading, rad, [-pi, pi)
    ("speed", "%.6f"),        # actual speed along the car's x, m/s
    ("steer", "%.6f"),        # actual bicycle-equivalent wheel angle, rad, + = left
    ("yaw_rate", "%.6f"),     # actual yaw rate, rad/s
    ("speed_cmd", "%.6f"),    # commanded speed after speed_norm, m/s
    ("steer_cmd", "%.6f"),    # commanded steering after turn_norm, rad
    ("yaw_rate_cmd", "%.6f"), # differential yaw rate from diff_norm, rad/s
    ("lap", "%d"),            # laps completed so far
    ("off_track", "%d"),      # 1 while any wheel is off the road
)
COLUMNS: tuple[str, ...] = tuple(name for name, _ in SCHEMA)
_LINE_FORMAT = ",".join(fmt for _, fmt in SCHEMA) + "\n"


class TelemetryLog:
    """Rows of :data:`COLUMNS` (tuples in that order), appended once per camera frame."""

    def __init__(self) -> None:
        self.rows: list[tuple] = []

    def append(self, row: tuple) -> None:
        self.rows.append(row)

    def __len__(self) -> int:
        return len(self.rows)

    def column(self, name: str) -> np.ndarray:
        """One column as a float array ``(N,)``."""
        i = COLUMNS.index(name)
        return np.array([r[i] for r in self.rows], dtype=float)

    def to_csv_text(self) -> str:
        return ",".join(COLUMNS) + "\n" + "".join(_LINE_FORMAT % r for r in self.rows)

    def write_csv(self, path: str | Path) -> Path:
        """Write the CSV atomically; raises :class:`SimError` if the file cannot be written."""
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        try:
            if path.parent and not path.parent.exists():
                path.parent.mkdir(parents=True, exist_ok=True)
            with open(tmp, "w", newline="") as fh:
                fh.write(self.to_csv_text())
            os.replace(tmp, path)
        except OSError as exc:
            raise SimError(f"{path}: cannot write telemetry CSV ({exc.strerror})") from None
        return path


def read_csv(path: str | Path) -> dict[str, np.ndarray]:
    """Read a telemetry CSV back: column name -> float array ``(N,)``."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise SimError(f"{path}: cannot read telemetry CSV ({exc.strerror})") from None
    lines = text.splitlines()
    if not lines:
        raise SimError(f"{path}:1: empty file, expected the header {','.join(COLUMNS)}")
    header = lines[0].split(",")
    missing = [c for c in ("t", "x", "y", "yaw", "speed", "steer", "speed_cmd", "steer_cmd")
               if c not in header]
    if missing:
        raise SimError(f"{path}:1: header lacks column(s) {', '.join(missing)}")
    try:
        data = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:] if ln.strip()],
                        dtype=float).reshape(-1, len(header))
    except ValueError as exc:
        raise SimError(f"{path}: bad number ({exc})") from None
    return {name: data[:, i] for i, name in enumerate(header)}
