"""Partial-sensor logs of the shared real car, made from its raw topic files.

What most NXP Cup teams can record is wheel speed and a gyro, no pose; others have only an
overhead camera or motion capture (a pose, no speed). The shared real data
(``REAL_DIR/raw/DS2``, ``.../DS3``: FrictionMaps, README there) hold a real car's topics
separately: ``odomData.csv`` (VESC wheel odometry, ``vx`` m/s), ``imuData.csv`` (VESC IMU,
``wz`` in deg/s, + = counter-clockwise), ``pfPoseData.csv`` (particle-filter pose: ``x``,
``y``, orientation quaternion), ``commandData.csv`` (the Ackermann command, ``V`` m/s,
``delta`` rad), each row stamped ROS-style (``s``, ``ns``). :func:`partial_log_csv` merges
them the way a team's logger or a pandas merge would - one row per message of the leading
sensor (odometry; the pose), the gyro interpolated at its stamp, the command last sent at or
before it - and keeps the topics' own column names, so the log is read through a column
mapping (:data:`COLUMNS`: split stamps, deg/s, a quaternion) as a team's own log would be.

Nothing is written into the repository: the CSV goes where the caller says.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

SENSORS = ("encoder_gyro", "pose")
_STAMP = 't_s={seconds = "sec", nanoseconds = "nsec"}'
_COMMAND = ("speed_cmd_mps=V", "steer_cmd_rad=delta")
COLUMNS = {
    "encoder_gyro": (_STAMP, "speed_mps=vx", 'yaw_rate_radps={column = "gyro_z", unit = "deg/s"}', *_COMMAND),
    "pose": (_STAMP, "x_m=x", "y_m=y", 'yaw_rad={quaternion = ["qx", "qy", "qz", "qw"]}', *_COMMAND),
}


def _topic(path: Path) -> dict[str, np.ndarray]:
    """A topic file's columns by header name (the unnamed first column included)."""
    with path.open(newline="") as f:
        reader = csv.reader(f)
        head = next(reader)
        data = np.array([[float(c) for c in row] for row in reader if row], dtype=float)
    return {name: data[:, i] for i, name in enumerate(head)}


def _stamp(topic: dict[str, np.ndarray]) -> np.ndarray:
    return topic["s"] + topic["ns"] * 1e-9


def partial_log_csv(raw_dir: Path, out: Path, sensors: str) -> int:
    """Write the ``sensors`` log (:data:`SENSORS`) of the data set in ``raw_dir`` to ``out``;
    returns its row count. Rows before the first command are left out (none known yet)."""
    cmd = _topic(raw_dir / "commandData.csv")
    if sensors == "encoder_gyro":
        lead, imu = _topic(raw_dir / "odomData.csv"), _topic(raw_dir / "imuData.csv")
        t = _stamp(lead)
        head = "vx,gyro_z"
        cols = [lead["vx"], np.interp(t, _stamp(imu), imu["wz"])]
    elif sensors == "pose":
        lead = _topic(raw_dir / "pfPoseData.csv")
        t = _stamp(lead)
        head = "x,y,qx,qy,qz,qw"
        cols = [lead[c] for c in ("x", "y", "q.x", "q.y", "q.z", "q.w")]
    else:
        raise ValueError(f"sensors: expected one of {', '.join(SENSORS)}, got {sensors!r}")
    last = np.searchsorted(_stamp(cmd), t, side="right") - 1
    rows = np.flatnonzero(last >= 0)
    with out.open("w", newline="") as f:
        f.write(f"sec,nsec,{head},V,delta\n")
        for i in rows:
            k = last[i]
            values = ",".join(f"{c[i]:.9g}" for c in cols)
            f.write(f"{int(lead['s'][i])},{int(lead['ns'][i])},{values},{cmd['V'][k]:.9g},{cmd['delta'][k]:.9g}\n")
    return int(rows.size)
