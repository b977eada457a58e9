"""Reading a ``track.json`` (format ``nxpcup-track/1``, docs/DESIGN.md "Track output
folder"): the one reader of the fields the simulator uses, for ``simrunner`` (driving) and
``trackgen validate`` (checking a build folder), so both accept and refuse the same files
with the same line.

:func:`read_track_json` returns the checked fields (absent ones are left out):
``name: str``, ``start_pose: Pose2``, ``finish_gate: (Pose2, half_width_m)``,
``length_m: float``, ``centreline: (N, 2)`` read-only float array, ``course``: a tuple of
``(index, kind, line, s_start_m, s_end_m)`` per pass in driving order (where each piece lies
along the centreline; files written before it have none); it raises
:class:`worlds.WorldError` (``file:line: message`` for bad JSON, ``file: field: expected
...`` for a bad field) and reads at most :data:`MAX_TRACK_JSON_BYTES`.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from pieces.pose import Pose2
from worlds.sdf_xml import WorldError

FORMAT_PREFIX = "nxpcup-track/"
MAX_TRACK_JSON_BYTES = 64 * 1024 * 1024  # a 10,000-piece layout's is ~20 MB


def load_json(path: str | Path) -> dict:
    """The JSON object of a track.json whose ``format`` starts with ``nxpcup-track/``."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_TRACK_JSON_BYTES:
            raise WorldError(f"{path}: {size / 2**20:.1f} MiB: at most "
                             f"{MAX_TRACK_JSON_BYTES // 2**20} MiB are read")
        data = json.loads(path.read_bytes())
    except OSError as exc:
        raise WorldError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except json.JSONDecodeError as exc:
        raise WorldError(f"{path}:{exc.lineno}: not valid JSON ({exc.msg}, column {exc.colno})") from None
    except (UnicodeDecodeError, RecursionError, ValueError) as exc:
        reason = "nested too deep" if isinstance(exc, RecursionError) else str(exc)[:80]
        raise WorldError(f"{path}: not valid JSON ({reason})") from None
    if not isinstance(data, dict) or not str(data.get("format", "")).startswith(FORMAT_PREFIX):
        raise WorldError(f"{path}: expected a JSON object with \"format\": \"nxpcup-track/1\"")
    return data


def _pose(value, where: str) -> Pose2:
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                       for v in value)):
        raise WorldError(f"{where}: expected [x_m, y_m, yaw_rad], got {_short(value)}")
    return Pose2(*value)


def _short(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def read_track_json(path: str | Path) -> dict:
    """The fields of a track.json the simulator uses, checked (module docstring)."""
    path = Path(path)
    data = load_json(path)
    out: dict = {}
    if isinstance(data.get("name"), str) and data["name"]:
        out["name"] = data["name"]
    if data.get("start_pose") is not None:
        out["start_pose"] = _pose(data["start_pose"], f"{path}: start_pose")
    gate = data.get("finish_gate")
    if gate is not None:
        half = gate.get("half_width_m") if isinstance(gate, dict) else None
        if (isinstance(half, bool) or not isinstance(half, (int, float))
                or not (half > 0 and math.isfinite(half))):
            raise WorldError(f"{path}: finish_gate: expected {{\"pose\": [x, y, yaw], "
                             f"\"half_width_m\": > 0}}, got {_short(gate)}")
        out["finish_gate"] = (_pose(gate.get("pose"), f"{path}: finish_gate.pose"), float(half))
    length = data.get("length_m")
    if length is not None:
        if (isinstance(length, bool) or not isinstance(length, (int, float))
                or not (length > 0 and math.isfinite(length))):
            raise WorldError(f"{path}: length_m: expected a positive number, got {_short(length)}")
        out["length_m"] = float(length)
    centre = data.get("centreline")
    if centre is not None:
        try:
            arr = np.asarray(centre, dtype=float) if isinstance(centre, list) else None
        except (TypeError, ValueError, OverflowError):
            arr = None
        if arr is None or arr.ndim != 2 or arr.shape[1] != 2 or len(arr) < 2 or not np.isfinite(arr).all():
            raise WorldError(f"{path}: centreline: expected a list of [x_m, y_m] points")
        arr.flags.writeable = False
        out["centreline"] = arr
    course = data.get("course")
    if course is not None:
        out["course"] = _course(course, path)
    hills = data.get("hills")
    if hills is not None:
        out["hills"] = _hills(hills, path)
    return out


def _hills(hills, path: Path):
    """track.json's ``hills`` as a :class:`worlds.terrain.Terrain`."""
    from worlds.terrain import Hill, Terrain

    if not isinstance(hills, list):
        raise WorldError(f"{path}: hills: expected a list of {{\"x_m\", \"y_m\", \"yaw_rad\", "
                         f"\"length_m\", \"height_m\", \"width_m\"}}, got {_short(hills)}")
    out = []
    for i, item in enumerate(hills):
        try:
            out.append(Hill.from_json(item))
        except ValueError as exc:
            raise WorldError(f"{path}: hills[{i}]: {exc}") from None
    return Terrain(tuple(out))


def _course(course, path: Path) -> tuple:
    expected = (f"{path}: course: expected a list of {{\"index\": int, \"kind\": str, \"line\": int, "
                f"\"s_start_m\": m, \"s_end_m\": m}} in driving order")
    if not isinstance(course, list):
        raise WorldError(expected)
    out = []
    last = 0.0
    for item in course:
        try:
            index, kind, line = item["index"], item["kind"], item["line"]
            a, b = float(item["s_start_m"]), float(item["s_end_m"])
        except (TypeError, KeyError, ValueError):
            raise WorldError(f"{expected}, got {_short(item)}") from None
        if (not all(isinstance(v, int) and not isinstance(v, bool) for v in (index, line))
                or not isinstance(kind, str) or not (math.isfinite(a) and math.isfinite(b))
                or not last - 1e-9 <= a <= b):
            raise WorldError(f"{expected}, got {_short(item)}")
        out.append((index, kind, line, a, b))
        last = b
    return tuple(out)
