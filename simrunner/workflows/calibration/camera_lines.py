"""Recorded camera lines, as teams log them over UART (``simrunner calibrate-camera``).

A file is CSV or whitespace-separated text, one frame a row:

* no header: ``W`` integers per row (``W = camera.width_px``, 128 for a TSL1401), 0..255;
* or a header row naming the columns: ``p0 .. p{W-1}`` (required), ``t_s`` (optional, s)
  and, for ``--scene track``, ``x_m``, ``y_m``, ``yaw_rad`` (the car's pose at each frame).

Blank lines and lines starting with ``#`` are skipped. A line whose pixels all read one value
is refused (a covered lens, an unclocked camera), except at the start of a file, where it is a
power-up frame. Every problem is one line naming the file, the line and what was expected
(:class:`CalibrationError`); nothing is guessed.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simrunner.workflows.calibration.measured import CalibrationError

MAX_FILE_BYTES = 64 * 1024 * 1024
POSE_COLUMNS = ("x_m", "y_m", "yaw_rad")
_SPLIT = re.compile(r"[,;\t ]+")


@dataclass(frozen=True)
class Recording:
    """Recorded lines: ``frames`` ``(N, W)`` float (ADC counts, 8-bit scale), their file and
    line numbers, ``t_s`` ``(N,)`` or None, ``poses`` ``(N, 3)`` (x_m, y_m, yaw_rad) or None.
    Frames of several files follow each other; ``file_starts`` marks where each file begins
    (its first frames may be start-up frames)."""

    frames: np.ndarray
    where: tuple[str, ...]
    t_s: np.ndarray | None
    poses: np.ndarray | None
    file_starts: tuple[int, ...]


def _number(cell: str) -> float | None:
    try:
        v = float(cell)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def read_file(path: str | Path, width: int, *, allow_flat: bool = False
              ) -> tuple[np.ndarray, list[str], np.ndarray | None, np.ndarray | None]:
    """One recording file: ``(frames, where, t_s, poses)`` (see :class:`Recording`).
    ``allow_flat``: lines that read one value everywhere are kept (a dark frame)."""
    path = Path(path)
    try:
        if path.stat().st_size > MAX_FILE_BYTES:
            raise CalibrationError(f"{path}: {path.stat().st_size / 2**20:.0f} MiB of lines: at most "
                                   f"{MAX_FILE_BYTES // 2**20} MiB are read")
        text = path.read_bytes().decode("utf-8-sig")
    except FileNotFoundError:
        raise CalibrationError(f"{path}: recorded lines not found") from None
    except IsADirectoryError:
        raise CalibrationError(f"{path}: is a folder, expected a file of recorded lines") from None
    except UnicodeDecodeError as exc:
        raise CalibrationError(f"{path}: not a text file of recorded lines (byte {exc.start} is not UTF-8)") from None
    except OSError as exc:
        raise CalibrationError(f"{path}: cannot read recorded lines ({exc.strerror or exc})") from None
    rows: list[list[float]] = []
    where: list[str] = []
    columns: dict[str, int] | None = None
    n_cells = width
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        cells = [c for c in _SPLIT.split(line) if c]
        if columns is None and not rows and _number(cells[0]) is None:
            columns = {name: i for i, name in enumerate(cells)}
            missing = [f"p{i}" for i in range(width) if f"p{i}" not in columns]
            if missing:
                raise CalibrationError(f"{path}:{lineno}: header without {', '.join(missing[:3])}"
                                       f"{' ...' if len(missing) > 3 else ''}: expected columns p0 .. "
                                       f"p{width - 1} (one per pixel of camera.width_px = {width}), optional "
                                       f"t_s, x_m, y_m, yaw_rad")
            n_cells = len(cells)
            continue
        if len(cells) != n_cells:
            raise CalibrationError(f"{path}:{lineno}: {len(cells)} values, expected {n_cells}"
                                   + (f" (one per pixel of camera.width_px = {width})" if columns is None
                                      else " (one per header column)"))
        values = []
        for i, cell in enumerate(cells):
            v = _number(cell)
            if v is None:
                raise CalibrationError(f"{path}:{lineno}: {cell[:20]!r} in column {i + 1} is not a number")
            values.append(v)
        rows.append(values)
        where.append(f"{path}:{lineno}")
    if not rows:
        raise CalibrationError(f"{path}: no recorded lines (empty file): expected one frame per row, "
                               f"{width} numbers 0..255")
    data = np.array(rows, dtype=np.float64)
    pix = data if columns is None else data[:, [columns[f"p{i}"] for i in range(width)]]
    bad = np.argwhere((pix < 0) | (pix > 255) | (pix != np.floor(pix)))
    if len(bad):
        r, c = bad[0]
        raise CalibrationError(f"{where[r]}: {pix[r, c]:g} at pixel {c}: expected a whole number 0..255 "
                               f"(8-bit lines; shift 10- or 12-bit readings right by 2 or 4)")
    flat = np.ptp(pix, axis=1) == 0
    lead = int(np.argmin(flat)) if not flat.all() else len(flat)  # leading flat frames: power-up
    later = np.flatnonzero(flat[lead:]) + lead
    if not allow_flat and (lead == len(flat) or len(later)):
        r = int(later[0]) if len(later) else 0
        raise CalibrationError(f"{where[r]}: every pixel reads {pix[r, 0]:g}: not a camera line of a "
                               f"track (lens covered, camera unplugged or not yet clocked?)")
    t_s = data[:, columns["t_s"]] if columns and "t_s" in columns else None
    poses = None
    if columns and all(c in columns for c in POSE_COLUMNS):
        poses = data[:, [columns[c] for c in POSE_COLUMNS]]
    return pix, where, t_s, poses


def read_recordings(paths, width: int) -> Recording:
    """Every file of ``paths`` in turn (:func:`read_file`)."""
    frames, where, times, poses, starts = [], [], [], [], []
    for path in paths:
        f, w, t, p = read_file(path, width)
        starts.append(sum(len(x) for x in frames))
        frames.append(f)
        where += w
        times.append(t)
        poses.append(p)
    t_all = np.concatenate(times) if all(t is not None for t in times) else None
    p_all = np.concatenate(poses) if all(p is not None for p in poses) else None
    return Recording(np.concatenate(frames), tuple(where), t_all, p_all, tuple(starts))
