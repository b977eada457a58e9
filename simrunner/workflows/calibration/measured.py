"""The measurements file of ``simrunner calibrate`` (TOML; docs/calibration.md).

Every section is optional; each holds the numbers of one thesis chapter-5 test:

    [camera]        distance_m                                    (Fig. 5.2)
    [speed]         commands, distances_m, window_s, settle_s, model, full_command, sim_norm  (5.2.1)
    [acceleration]  speed_mps | command, time_s, distance_m       (5.2.2)
    [braking]       speed_mps | command, distance_m               (5.2.3)
    [steering]      radius_m, measured_at, speed_mps              (5.3.1)
    [traction]      slip_angle_deg, orientation                   (5.4)
    [mass]          weight_kg, scale                              (5.5)
    [duty]          hbridge, duties + speeds_mps, accel_duty + accel_time_s + accel_distance_m,
                    coast_speed_mps + coast_distance_m (+ coast_time_s)   (the motor model, duty.py)

:func:`load_measurements` checks types, ranges and unknown names and raises
:class:`CalibrationError` with one line ``path:line: section.key: expected ...``.
"""
from __future__ import annotations

import math
import re
from vehicle.userfiles import read_user_toml
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from simrunner.errors import SimError


class CalibrationError(SimError):
    """Bad measurements file, or measurements the simulated car cannot reproduce."""


# section -> key -> (kind, lo, hi, default); kind: "num", "nums", "str:a|b|c"; default
# REQUIRED means the key must be given, None means optional without a default.
REQUIRED = object()
SCHEMA: dict[str, dict[str, tuple]] = {
    "camera": {"distance_m": ("num", 0.0, 5.0, REQUIRED)},
    "speed": {"commands": ("nums", -1e9, 1e9, REQUIRED), "distances_m": ("nums", 0.0, 1000.0, REQUIRED),
              "window_s": ("num", 0.0, 60.0, 2.0), "settle_s": ("num", 0.0, 60.0, 1.0),
              "model": ("str:linear|proportional|quadratic", None, None, "linear"),
              "full_command": ("num", -1e9, 1e9, None), "sim_norm": ("num", 0.0, 1e6, 1.0)},
    "acceleration": {"speed_mps": ("num", 0.0, 30.0, None), "command": ("num", -1e9, 1e9, None),
                     "time_s": ("num", 0.0, 30.0, REQUIRED), "distance_m": ("num", 0.0, 500.0, REQUIRED)},
    "braking": {"speed_mps": ("num", 0.0, 30.0, None), "command": ("num", -1e9, 1e9, None),
                "distance_m": ("num", 0.0, 100.0, REQUIRED)},
    "steering": {"radius_m": ("num", 0.0, 20.0, REQUIRED),
                 "measured_at": ("str:inner_rear_wheel|rear_axle_centre|outer_front_wheel", None, None,
                                 "inner_rear_wheel"),
                 "speed_mps": ("num", 0.05, 2.0, 0.5)},
    "traction": {"slip_angle_deg": ("num", 0.0, 68.0, REQUIRED),
                 "orientation": ("str:downhill|sideways", None, None, "downhill")},
    "mass": {"weight_kg": ("num", 0.0, 50.0, REQUIRED), "scale": ("num", 0.0, 10.0, 1.0)},
    # the motor model of a duty-driven car (duty.py): any of three tests
    "duty": {"hbridge": ("str:brake|coast", None, None, None),
             "duties": ("nums", 0.0, 1.0, None), "speeds_mps": ("nums", 0.0, 30.0, None),
             "accel_duty": ("num", 0.0, 1.0, 1.0), "accel_time_s": ("num", 0.0, 30.0, None),
             "accel_distance_m": ("num", 0.0, 500.0, None),
             "coast_speed_mps": ("num", 0.0, 30.0, None), "coast_distance_m": ("num", 0.0, 500.0, None),
             "coast_time_s": ("num", 0.0, 120.0, None)},
    # the camera procedures (camera_procedures.py): files of recorded lines, relative to this file
    "camera_dark": {"lines": ("path", None, None, REQUIRED), "exposure_s": ("num", 0.0, 1.0, None)},
    "camera_flat": {"lines": ("path", None, None, REQUIRED)},
    "camera_sweep": {"exposures_s": ("nums", 0.0, 1.0, REQUIRED), "lines": ("paths", None, None, REQUIRED)},
}
THESIS = {"camera": "Fig. 5.2", "speed": "5.2.1", "acceleration": "5.2.2", "braking": "5.2.3",
          "steering": "5.3.1", "traction": "5.4", "mass": "5.5"}
# where each procedure comes from (the report's headings, the car file's source comments)
SOURCES = {**{k: f"thesis {v}" for k, v in THESIS.items()},
           "duty": "motor model (c1 - c2 v) d, Liniger et al. 2015", "camera_dark": "EMVA 1288 (dark measurements)",
           "camera_flat": "EMVA 1288 (flat field, PRNU)", "camera_sweep": "EMVA 1288 (photon transfer)"}
ORDER = ("mass", "traction", "steering", "speed", "acceleration", "braking", "duty", "camera_dark", "camera_flat",
         "camera_sweep", "camera")


@dataclass(frozen=True)
class Measurements:
    """Checked measurements: section name -> {key: value} (defaults filled in); ``path``
    for messages."""

    sections: dict[str, dict[str, Any]]
    path: str = "<measurements>"
    text: str = ""  # the file's text, for line numbers in messages

    def __contains__(self, section: str) -> bool:
        return section in self.sections

    def __getitem__(self, section: str) -> dict[str, Any]:
        return self.sections[section]

    def where(self, section: str, key: str | None = None) -> str:
        """``path:line: section.key`` (the line when it can be found) for messages."""
        line = _line_of(self.text, section, key) if self.text else None
        if line is None and key is not None and self.text:
            line = _line_of(self.text, section, None)
        return f"{self.path}{':' + str(line) if line else ''}: {section}" + (f".{key}" if key else "")


def _line_of(text: str, section: str, key: str | None) -> int | None:
    """1-based line of ``key`` inside ``[section]`` (or of the section header)."""
    current = None
    for i, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        m = re.match(r"\[\s*([A-Za-z0-9_\-]+)\s*\]", s)
        if m:
            current = m.group(1)
            if key is None and current == section:
                return i
            continue
        if current == section and key is not None and re.match(rf"{re.escape(key)}\s*=", s):
            return i
    return None


def _check_value(kind: str, lo, hi, value: Any) -> tuple[Any, str | None]:
    """(converted value, None) or (None, 'expected ...')."""
    if kind == "num":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            return None, "expected a finite number"
        open_lo = lo == 0.0  # zero lower bounds are exclusive: a distance of 0 is no measurement
        if not ((lo < value if open_lo else lo <= value) and value <= hi):
            return None, f"expected a number in {'(' if open_lo else '['}{lo:g}, {hi:g}]"
        return float(value), None
    if kind == "nums":
        if not isinstance(value, list) or not value:
            return None, "expected a non-empty list of numbers"
        out = []
        for v in value:
            conv, err = _check_value("num", lo, hi, v)
            if err:
                return None, f"expected a list of numbers ({err.replace('expected ', '')}), got {v!r}"
            out.append(conv)
        return out, None
    if kind == "path":
        if not isinstance(value, str) or not value.strip():
            return None, "expected a file name (of recorded lines)"
        return value, None
    if kind == "paths":
        if not isinstance(value, list) or not value or not all(isinstance(x, str) and x.strip() for x in value):
            return None, "expected a non-empty list of file names (of recorded lines)"
        return value, None
    options = kind.split(":", 1)[1].split("|")
    if value not in options:
        return None, f"expected one of {', '.join(repr(o) for o in options)}"
    return value, None


def measurements_from_dict(data: dict[str, Any], path: str = "<measurements>", text: str = "") -> Measurements:
    """Check ``data`` (parsed TOML) against :data:`SCHEMA`; see the module docstring."""

    def fail(section: str, key: str | None, message: str):
        line = (_line_of(text, section, key) or _line_of(text, section, None)) if text else None
        where = f"{path}:{line}" if line else path
        raise CalibrationError(f"{where}: {section}{'.' + key if key else ''}: {message}")

    sections: dict[str, dict[str, Any]] = {}
    for section, values in data.items():
        spec = SCHEMA.get(section)
        if spec is None:
            fail(section, None, f"unknown section (expected one of {', '.join(SCHEMA)})")
        if not isinstance(values, dict):
            fail(section, None, "expected a table [" + section + "]")
        out: dict[str, Any] = {}
        for key, value in values.items():
            if key not in spec:
                fail(section, key, f"unknown key (expected one of {', '.join(spec)})")
            kind, lo, hi, _ = spec[key]
            conv, err = _check_value(kind, lo, hi, value)
            if err:
                fail(section, key, err)
            out[key] = conv
        for key, (_, _, _, default) in spec.items():
            if key not in out:
                if default is REQUIRED:
                    fail(section, key, "missing (required in this section)")
                out[key] = default
        _check_section(section, out, lambda key, msg, s=section: fail(s, key, msg))
        sections[section] = out
    return Measurements(sections, path, text)


def _check_section(section: str, v: dict[str, Any], fail) -> None:
    """Cross-field rules."""
    if section == "speed":
        need = {"linear": 2, "proportional": 1, "quadratic": 3}[v["model"]]
        if len(v["distances_m"]) != len(v["commands"]):
            fail("distances_m", f"expected {len(v['commands'])} values, one per command")
        if len(set(v["commands"])) < need:
            fail("commands", f"expected at least {need} different commands for model '{v['model']}'")
    if section == "duty":
        pairs = (("duties", "speeds_mps"), ("accel_time_s", "accel_distance_m"),
                 ("coast_speed_mps", "coast_distance_m"))
        for a, b in pairs:
            if (v[a] is None) != (v[b] is None):
                given, missing = (a, b) if v[b] is None else (b, a)
                fail(given, f"expected {missing} with it")
        if all(v[a] is None for a, _ in pairs):
            fail(None, "expected at least one test: duties + speeds_mps (steady speeds), accel_time_s + "
                       "accel_distance_m (0 -> duty) or coast_speed_mps + coast_distance_m (coast-down)")
        if v["duties"] is not None and len(v["duties"]) != len(v["speeds_mps"]):
            fail("speeds_mps", f"expected {len(v['duties'])} values, one per duty")
        if v["coast_time_s"] is not None and v["coast_speed_mps"] is None:
            fail("coast_time_s", "expected together with coast_speed_mps and coast_distance_m")
    if section in ("acceleration", "braking"):
        if (v["speed_mps"] is None) == (v["command"] is None):
            fail("speed_mps", "expected exactly one of speed_mps (m/s) or command (with a [speed] section)")


def load_measurements(path: str | Path) -> Measurements:
    """Read and check a measurements TOML file."""
    path = Path(path)
    text, data = read_user_toml(path, "measurements", CalibrationError)
    m = measurements_from_dict(data, str(path), text)
    if not m.sections:
        raise CalibrationError(f"{path}: no measurements: expected at least one of the sections "
                               f"{', '.join('[' + s + ']' for s in SCHEMA)}")
    return m
