"""The run log: one frozen, typed, columnar record of a run, with one writer and one reader.

Every log of the project is a :class:`RunLog`: the telemetry of ``simrunner drive``, the
simulated logs of ``simrunner excite --simulate`` and a car's measured log read by
``simrunner gap``. Columns carry their unit in their name (:data:`COLUMNS`; the schema is
documented once, in docs/telemetry.md). Only ``t_s`` is required: a measured log holds the
columns its sensors gave (a column that is absent is ``None``), and each workflow asks for
the ones it needs with :meth:`RunLog.require`.

File (CSV): a first line ``# nxpcup-sim run log, format 2``, a header of column names,
then one line per row; numbers in fixed formats (``%d`` and ``%.6f``; so the same run gives
the same bytes), ``data_text`` quoted by the CSV rules when it needs to be. Written
atomically (``PATH.tmp``, then renamed). :func:`read_log` also reads format 1 (the header of
names without units, ``t,x,y,yaw,speed,...``, no format line), and any CSV with these
columns in any order; unknown columns are ignored. Cells are separated by commas, or by
semicolons or tabs when the header line has no comma (a spreadsheet's export); in a
semicolon file a number may use a decimal comma (``0,02``; :func:`_delimiter`). A run log of
this simulator whose last line has no line end was cut short while it was written (the
process was killed): that line is left out, with a :class:`LogWarning`; every complete row
is read.

During a run, :class:`RunRecorder` collects the rows: the state at each camera frame
boundary ``t_k``, the command the first physics step after ``t_k`` applies (the
controller's answer to frame ``k``; the last row keeps the command in force at its
boundary), and the ``add_data`` text lines added between ``t_k`` and ``t_k+1``. It streams
each row to the CSV as the run goes (:mod:`simrunner.telemetry.stream`, the same bytes as
:func:`write_log`) and keeps a bounded number in memory.
"""
from __future__ import annotations

import csv
import io
import math
import re
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Mapping, Protocol, Sequence

import numpy as np

from simrunner.errors import SimError
from simrunner.telemetry.sparse import is_empty_cell
from vehicle.userfiles import write_atomic



class ColumnMap(Protocol):
    """What :func:`read_log` asks of a column mapping (:class:`simrunner.telemetry.columns.ColumnMap`,
    which builds on this module): its rules, the CSV columns to read, and the mapped values."""

    rules: tuple

    def columns_to_read(self, header: Sequence[str], header_line: int, source: str) -> dict[str, int]: ...

    def apply(self, cells: Mapping[str, Sequence[str]], rows: int, source: str, *, merged: bool = False) -> dict: ...

FORMAT_VERSION = 2
FORMAT_LINE = f"# nxpcup-sim run log, format {FORMAT_VERSION}"
# No car reaches these (a position of a planet's size, a speed or turn rate of a rifle bullet
# in a minute's log); a value beyond one is a unit or mapping error, read before anything
# squares it into an overflow. Positions allow UTM coordinates (northing to 1e7 m).
MAGNITUDE_LIMITS = {"m": 1e8, "m/s": 1e4, "rad": 1e5, "rad/s": 1e4, "m/s^2": 1e5}
TEXT_SEPARATOR = " | "  # between the add_data text lines of one row


class LogError(SimError):
    """A log file or log columns are malformed. ``str(err)`` is ``path:line: what was
    expected``, or ``path: what was expected`` for the file as a whole (``line`` 0)."""

    def __init__(self, path: str, line: int, message: str):
        self.path, self.line, self.message = str(path), int(line), message
        # one line, whatever the file holds (a quoted cell may contain a line break)
        where = f"{self.path}:{self.line}" if self.line else self.path
        text = f"{where}: {message}".replace("\r", "\\r").replace("\n", "\\n")
        super().__init__(text)


class LogWarning(UserWarning):
    """A log was read with something left out (a last line cut short)."""


@dataclass(frozen=True)
class Column:
    """One column of the schema: name (unit in it), unit, kind, file format, meaning."""

    name: str
    unit: str
    kind: str  # "int" | "float" | "flag" (0/1) | "text"
    fmt: str
    meaning: str


COLUMNS: tuple[Column, ...] = (
    Column("frame", "-", "int", "%d", "camera frame index (row index in excitation logs)"),
    Column("t_s", "s", "float", "%.6f", "time"),
    Column("x_m", "m", "float", "%.6f", "world x of the car frame origin (rear-axle midpoint)"),
    Column("y_m", "m", "float", "%.6f", "world y of the same point"),
    Column("yaw_rad", "rad", "float", "%.6f", "heading, counter-clockwise from world +x"),
    Column("speed_mps", "m/s", "float", "%.6f", "actual speed along the car's x (negative = reversing)"),
    Column("steer_rad", "rad", "float", "%.6f", "actual bicycle-equivalent steering angle, + = left"),
    Column("yaw_rate_radps", "rad/s", "float", "%.6f", "actual yaw rate, + = counter-clockwise"),
    Column("speed_cmd_mps", "m/s", "float", "%.6f", "commanded speed (after speed_norm)"),
    Column("steer_cmd_rad", "rad", "float", "%.6f", "commanded steering (after turn_norm)"),
    Column("yaw_rate_cmd_radps", "rad/s", "float", "%.6f", "differential yaw rate (diff_norm)"),
    Column("coast", "0/1", "flag", "%d", "drive off, rear wheels rolling freely"),
    Column("lap", "-", "int", "%d", "laps completed so far"),
    Column("off_track", "0/1", "flag", "%d", "a wheel's contact patch is entirely off the road"),
    Column("z_m", "m", "float", "%.6f", "height of the car frame origin above the track's surface "
                                        "(runs on tracks with hills)"),
    Column("pitch_rad", "rad", "float", "%.6f", "pitch of the car, + = nose down (runs on tracks with hills)"),
    *(Column(f"enc_{w}", "count", "int", "%d", f"count of the {w.upper()} wheel's encoder at the frame "
             "(runs of a car file with [encoders], its wheels)") for w in ("fl", "fr", "rl", "rr")),
    *(Column(f"gyro_{a}_radps", "rad/s", "float", "%.6f", f"the IMU's gyroscope about the car's {a} axis, sampled "
             "at the frame (runs of a car file with [imu])") for a in "xyz"),
    *(Column(f"accel_{a}_mps2", "m/s^2", "float", "%.6f", f"the IMU's accelerometer along the car's {a} axis "
             "(specific force: +9.81 up at rest), sampled at the frame (runs of a car file with [imu])")
      for a in "xyz"),
    Column("duty_left", "-", "float", "%.6f", "the left rear motor's duty -1..1 in force (runs of a car file "
                                              "with drive.command = \"duty\")"),
    Column("duty_right", "-", "float", "%.6f", "the right rear motor's duty -1..1 in force (duty drive)"),
    Column("duty_cmd", "-", "float", "%.6f", "the one duty of both motors set_speed gave, after speed_norm and "
                                             "the -1..1 clamp (NaN while set_motors' own duties are in force)"),
    Column("data_text", "-", "text", "%s", "the controller's add_data text of this frame"),
)
COLUMN_NAMES: tuple[str, ...] = tuple(c.name for c in COLUMNS)
_BY_NAME = {c.name: c for c in COLUMNS}
# format 1 (no units in the names) -> format 2
FORMAT1_NAMES = {"t": "t_s", "x": "x_m", "y": "y_m", "yaw": "yaw_rad", "speed": "speed_mps",
                 "steer": "steer_rad", "yaw_rate": "yaw_rate_radps", "speed_cmd": "speed_cmd_mps",
                 "steer_cmd": "steer_cmd_rad", "yaw_rate_cmd": "yaw_rate_cmd_radps"}


@dataclass(frozen=True, eq=False)
class CommandSteps:
    """The commands of a merged log at their own stamps (:func:`simrunner.telemetry.sparse.command_steps`):
    one entry per command message, every command column held at its last value, shape (M,),
    ``t_s`` strictly increasing. A log read a row per leading-sensor sample keeps them so a
    replay can apply a command sent between two rows when it was sent; ``coast`` is None
    when the log has none."""

    t_s: np.ndarray
    speed_cmd_mps: np.ndarray
    steer_cmd_rad: np.ndarray
    coast: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t_s.size)


@dataclass(frozen=True, eq=False)
class Repeats:
    """The rows a reader left out because each was stamped the same as the row before it
    (``read_log(repeated_stamps=True)``), shape (M,): their stamps, their file lines, and
    for each the columns whose values differ from the row kept (``""``: a copy of it). A
    logger that wrote one message twice, or two messages in one clock tick, gives them;
    :func:`simrunner.workflows.gap.glitches.find_glitches` lists them as duplicates."""

    t_s: np.ndarray
    lines: tuple[int, ...]
    differ: tuple[str, ...]

    def __len__(self) -> int:
        return int(self.t_s.size)


@dataclass(frozen=True, eq=False)
class RunLog:
    """A run's rows as read-only columns, each ``(N,)`` (``data_text`` a tuple of N str).

    Numeric columns are float64 (``frame`` and ``lap`` int64, flags bool); a column the log
    does not have is ``None``. ``source`` names where it came from (file path or a label).
    ``command_steps``: a merged log's commands at their own stamps (:class:`CommandSteps`;
    None for a log with a row per command), kept by :meth:`subset` and :meth:`with_columns`
    (unless it replaces a command column). ``repeats``: the rows the reader left out for
    repeating the previous row's stamp (:class:`Repeats`; None when it left none out).
    ``header_line``: the line of ``source`` holding the header (after comment lines), which
    :meth:`require` names; row ``i`` is then about line ``header_line + 1 + i``.
    """

    t_s: np.ndarray
    frame: np.ndarray | None = None
    x_m: np.ndarray | None = None
    y_m: np.ndarray | None = None
    yaw_rad: np.ndarray | None = None
    speed_mps: np.ndarray | None = None
    steer_rad: np.ndarray | None = None
    yaw_rate_radps: np.ndarray | None = None
    speed_cmd_mps: np.ndarray | None = None
    steer_cmd_rad: np.ndarray | None = None
    yaw_rate_cmd_radps: np.ndarray | None = None
    coast: np.ndarray | None = None
    lap: np.ndarray | None = None
    off_track: np.ndarray | None = None
    z_m: np.ndarray | None = None
    pitch_rad: np.ndarray | None = None
    enc_fl: np.ndarray | None = None
    enc_fr: np.ndarray | None = None
    enc_rl: np.ndarray | None = None
    enc_rr: np.ndarray | None = None
    gyro_x_radps: np.ndarray | None = None
    gyro_y_radps: np.ndarray | None = None
    gyro_z_radps: np.ndarray | None = None
    accel_x_mps2: np.ndarray | None = None
    accel_y_mps2: np.ndarray | None = None
    accel_z_mps2: np.ndarray | None = None
    duty_left: np.ndarray | None = None
    duty_right: np.ndarray | None = None
    duty_cmd: np.ndarray | None = None
    data_text: tuple[str, ...] | None = None
    source: str = "<log>"
    command_steps: CommandSteps | None = None
    repeats: Repeats | None = None
    header_line: int = 1

    def __len__(self) -> int:
        return int(self.t_s.size)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0]) if len(self) else 0.0

    @property
    def names(self) -> tuple[str, ...]:
        """The columns this log has, in schema order."""
        return tuple(n for n in COLUMN_NAMES if getattr(self, n) is not None)

    def column(self, name: str) -> np.ndarray:
        """Column ``name`` (numeric columns as float64); raises :class:`LogError` if absent."""
        if name not in _BY_NAME:
            raise LogError(self.source, 0, f"no column {name!r} in the schema (expected one of "
                                           f"{', '.join(COLUMN_NAMES)})")
        value = getattr(self, name)
        if value is None:
            raise LogError(self.source, 1, f"the log has no column {name!r}")
        return value

    def require(self, *names: str, min_rows: int = 1, min_duration_s: float = 0.0) -> None:
        """Raise :class:`LogError` unless the log has ``names`` and enough data."""
        missing = [n for n in names if getattr(self, n, None) is None]
        if missing:
            raise LogError(self.source, self.header_line, f"expected columns {', '.join(names)} "
                                           f"(missing: {', '.join(missing)})")
        if not len(self) and min_rows > 0:
            raise LogError(self.source, self.header_line, "expected rows of data after the header (got none)")
        if len(self) < min_rows or self.duration_s < min_duration_s:
            want = f"{min_rows} rows and {min_duration_s:g} s" if min_duration_s > 0.0 else f"{min_rows} rows"
            raise LogError(self.source, self.header_line + len(self),
                           f"expected at least {want} of data (got {len(self)} rows, {self.duration_s:.3g} s)")

    def coasting(self) -> np.ndarray:
        """``(N,) bool``: drive off at each row (all False without a ``coast`` column)."""
        return np.zeros(len(self), dtype=bool) if self.coast is None else self.coast

    def columns(self) -> dict[str, np.ndarray | tuple[str, ...]]:
        """The present columns by name, in schema order."""
        return {n: getattr(self, n) for n in self.names}

    def subset(self, rows: slice | np.ndarray | int) -> "RunLog":
        """The rows ``rows`` (a slice, an index array, or ``stop`` for the first rows)."""
        if isinstance(rows, (int, np.integer)):
            rows = slice(0, int(rows))
        cols = {}
        for n, v in self.columns().items():
            if n == "data_text":
                cols[n] = tuple(np.asarray(v, dtype=object)[rows]) if len(v) else ()
            else:
                cols[n] = v[rows]
        out = log_from_columns(cols, self.source, self.command_steps)
        if self.repeats is None or not len(out):
            return out
        r = self.repeats
        inside = np.flatnonzero((r.t_s >= out.t_s[0]) & (r.t_s <= out.t_s[-1]))
        if not inside.size:
            return out
        return _with_repeats(out, Repeats(r.t_s[inside], tuple(r.lines[i] for i in inside),
                                          tuple(r.differ[i] for i in inside)))

    def with_columns(self, **columns) -> "RunLog":
        """A copy with the given columns replaced or added (checked like any log); a new
        command column (``speed_cmd_mps``, ``steer_cmd_rad``, ``coast``) drops the
        ``command_steps``, which would no longer match the rows."""
        cols = dict(self.columns())
        cols.update(columns)
        steps = None if {"speed_cmd_mps", "steer_cmd_rad", "coast"} & set(columns) else self.command_steps
        out = log_from_columns({k: v for k, v in cols.items() if v is not None}, self.source, steps)
        return out if self.repeats is None else _with_repeats(out, self.repeats)


def _with_repeats(log: RunLog, repeats: Repeats | None) -> RunLog:
    return replace(log, repeats=repeats)


def log_from_columns(columns: dict, source: str = "<log>", command_steps: CommandSteps | None = None) -> RunLog:
    """Build and check a :class:`RunLog` from arrays keyed by schema names (format-1 names
    are accepted too; unknown keys are ignored). Line numbers in errors count the header as
    line 1, as in a file without the format line. ``command_steps``: see :class:`RunLog`."""
    cols = {FORMAT1_NAMES.get(k, k): v for k, v in columns.items()}
    if "t_s" not in cols:
        raise LogError(source, 1, "expected a time column t_s")
    out: dict = {}
    n = None
    for c in COLUMNS:
        if c.name not in cols or cols[c.name] is None:
            continue
        raw = cols[c.name]
        if c.kind == "text":
            arr = tuple("" if v is None else str(v) for v in raw)
            size = len(arr)
        else:
            a = np.asarray(raw, dtype=float).reshape(-1)
            size = a.size
            bad = np.flatnonzero(~np.isfinite(a) & ~(np.isnan(a) if c.name in NAN_COLUMNS else False))
            if bad.size:
                raise LogError(source, int(bad[0]) + 2, f"column {c.name!r}: expected a finite number"
                               + (" or nan" if c.name in NAN_COLUMNS else ""))
            if c.kind == "flag":
                bad = np.flatnonzero((a != 0.0) & (a != 1.0))
                if bad.size:
                    raise LogError(source, int(bad[0]) + 2, f"column {c.name!r}: expected 0 or 1")
                arr = a == 1.0
            elif c.kind == "int":
                bad = np.flatnonzero(a != np.round(a))
                if bad.size:
                    raise LogError(source, int(bad[0]) + 2, f"column {c.name!r}: expected a whole number")
                arr = a.astype(np.int64)
            else:
                limit = MAGNITUDE_LIMITS.get(c.unit)
                bad = np.flatnonzero(np.abs(a) > limit) if limit is not None else ()
                if len(bad):
                    raise LogError(source, int(bad[0]) + 2, f"column {c.name!r}: expected at most {limit:g} {c.unit} "
                                                            f"in magnitude (got {float(a[bad[0]]):.6g}): a unit or "
                                                            "mapping error?")
                arr = a.copy()
            arr.flags.writeable = False
        if n is None:
            n = size
        elif size != n:
            raise LogError(source, 1, f"expected every column to have {n} values ({c.name!r} has {size})")
        out[c.name] = arr
    t = out["t_s"]
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if bad.size:
        i = int(bad[0]) + 1
        raise LogError(source, i + 2, f"column 't_s': expected strictly increasing time (got "
                                      f"{float(t[i])!r} after {float(t[i - 1])!r})")
    return RunLog(source=str(source), command_steps=command_steps, **out)


# -- writing -------------------------------------------------------------------------------
def _quote(text: str) -> str:
    if any(ch in text for ch in ',"\n\r'):
        return '"' + text.replace('"', '""') + '"'
    return text


def to_csv_text(log: RunLog, *, float_format: str = "%.6f") -> str:
    """The file's text (see the module docstring). ``float_format`` replaces ``%.6f`` (e.g.
    ``"%r"``-like ``"%.17g"`` for a lossless copy)."""
    names = log.names
    fmts = [(_BY_NAME[n].fmt if _BY_NAME[n].fmt != "%.6f" else float_format) for n in names]
    columns = []
    for n in names:
        v = getattr(log, n)
        if n == "data_text":
            columns.append([_quote(s) for s in v])
        elif _BY_NAME[n].kind == "flag":
            columns.append(v.astype(np.int64).tolist())
        else:
            columns.append(v.tolist())
    line = ",".join(fmts) + "\n"
    body = "".join(line % row for row in zip(*columns)) if columns else ""
    return FORMAT_LINE + "\n" + ",".join(names) + "\n" + body


def write_log(log: RunLog, path: str | Path, *, float_format: str = "%.6f") -> Path:
    """Write ``log`` as CSV atomically; raises :class:`LogError` if it cannot be written."""
    path = Path(path)
    try:
        if path.parent and not path.parent.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, to_csv_text(log, float_format=float_format))
    except OSError as exc:
        raise LogError(str(path), 0, f"cannot write the log ({exc.strerror})") from None
    return path


# -- reading -------------------------------------------------------------------------------
def read_log(path: str | Path, columns: ColumnMap | None = None, *, merged: bool = False,
             repeated_stamps: bool = False) -> RunLog:
    """Read a log CSV (format 2 or 1, see the module docstring); raise :class:`LogError`
    (``path:line: what was expected``) for anything malformed.

    ``columns`` (a :class:`simrunner.telemetry.columns.ColumnMap`) reads a CSV whose columns have
    other names or units: each schema column it has a rule for is computed from the file's
    columns, the others are read by their own names (docs/telemetry.md, "Logs with other
    columns or units"). Without it, or with an empty map, the file is read as above.

    ``merged``: the CSV may be a merged topic log, each row holding the cells of the sensor
    that sent it and empty (or ``nan``) cells for the others; it is read as one row per
    sample of the leading sensor (:mod:`simrunner.telemetry.sparse`). A log without empty cells
    reads the same either way.

    ``repeated_stamps``: a row stamped the same as the row before it (after the mapping and
    the merge) is left out instead of refused, and recorded in ``RunLog.repeats`` (the first
    row of a stamp is kept); a stamp that goes back is still refused. For measured logs
    (``simrunner gap``), whose loggers sometimes write a message twice."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise LogError(str(path), 0, f"expected a readable CSV file ({exc.strerror})") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise LogError(str(path), 1, "expected a text (CSV) file") from None
    if "\0" in text:
        raise LogError(str(path), 1, "expected a text (CSV) file")
    text = _without_cut_line(text, str(path))
    return _parse(text, str(path), columns if columns is not None and columns.rules else None, merged,
                  repeated_stamps)


def _without_cut_line(text: str, source: str) -> str:
    """``text`` without its last line when that line was cut short: a run log of this
    simulator (it starts with the format line) always ends its rows with a line end, so text
    after the last one is a row a killed process did not finish writing (the rows before it
    are whole: each was written with one call). Warns :class:`LogWarning` naming the line."""
    if not text.startswith("# nxpcup-sim run log") or text.endswith("\n"):
        return text
    keep = pos = 0
    quotes = 0
    while True:  # the end of the last whole record: a line end outside quotes
        end = text.find("\n", pos)
        if end < 0:
            break
        quotes += text.count('"', pos, end)
        pos = end + 1
        if quotes % 2 == 0:
            keep = pos
    if text.count("\n", 0, keep) < 2:  # no header yet: nothing to keep
        return text
    line = text.count("\n", 0, keep) + 1
    warnings.warn(f"{source}:{line}: the last row is cut short (the run was killed while "
                  f"writing it); read without it", LogWarning, stacklevel=3)
    return text[:keep]


_DECIMAL_COMMA = re.compile(r"\s*[-+]?\d*,\d+(?:[eE][-+]?\d+)?\s*")


def _delimiter(text: str) -> str:
    """The cell separator of a CSV text: ``,``, else ``;`` or a tab when the header line (its
    first line that is neither empty nor a ``#`` comment) has no comma but one of them."""
    for line in text.splitlines():
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        if "," not in line:
            for sep in (";", "\t"):
                if sep in line:
                    return sep
        return ","
    return ","


def _decimal_points(row: list[str]) -> list[str]:
    """The cells of a semicolon-separated row with decimal commas written with points."""
    return [c.replace(",", ".") if _DECIMAL_COMMA.fullmatch(c) else c for c in row]


def _drop_repeated_stamps(values: dict, lines: list[int]) -> tuple[dict, list[int], Repeats | None]:
    """``values`` and ``lines`` without the rows stamped the same as the row before them,
    and those rows as :class:`Repeats` (None when there are none)."""
    try:
        t = np.asarray(values["t_s"], dtype=float)
    except (KeyError, TypeError, ValueError):
        return values, lines, None  # log_from_columns names what is wrong
    again = np.flatnonzero(np.diff(t) == 0.0) + 1
    if not again.size:
        return values, lines, None
    keep = np.ones(t.size, dtype=bool)
    keep[again] = False
    first = np.maximum.accumulate(np.where(keep, np.arange(t.size), 0))  # the row kept for each
    differ = []
    for i in again:
        j = int(first[i])
        names = []
        for name, v in values.items():
            a, b = v[i], v[j]
            if not (a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))):
                names.append(name)
        differ.append(",".join(names))
    rows = np.flatnonzero(keep)
    out = {k: (tuple(v[i] for i in rows) if isinstance(v, tuple) else
               [v[i] for i in rows] if isinstance(v, list) else np.asarray(v)[rows]) for k, v in values.items()}
    return out, [lines[i] for i in rows], Repeats(t[again], tuple(lines[i] for i in again), tuple(differ))


def _parse(text: str, source: str, columns: ColumnMap | None = None, merged: bool = False,
           repeated_stamps: bool = False) -> RunLog:
    delimiter = _delimiter(text)
    # a field as long as the file reads (the writer bounds no add_data text; the csv module's
    # default limit, 128 KiB, refused the log of a run that drew long texts); only ever raised
    csv.field_size_limit(max(csv.field_size_limit(), len(text)))
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    header, header_line = None, 1
    try:
        for row in reader:
            if row and row[0].lstrip().startswith("#"):
                _check_format_line(",".join(row), source, reader.line_num)
                continue
            if not row or all(not c.strip() for c in row):
                continue
            header, header_line = [h.strip() for h in row], reader.line_num
            named = list(header)  # as the file names them
            if columns is None:
                header = [FORMAT1_NAMES.get(h, h) for h in header]
            break
        if header is None:
            raise LogError(source, 1, f"expected a header line with columns such as "
                                      f"{', '.join(COLUMN_NAMES[:6])}, ...")
        if columns is not None:  # the map's source columns, as text; it converts them
            wanted = [(i, h) for h, i in columns.columns_to_read(header, reader.line_num, source).items()]
        elif "t_s" not in header:
            raise LogError(source, reader.line_num, "expected a time column t_s (or t) in the header")
        else:
            wanted = [(i, h) for i, h in enumerate(header) if h in _BY_NAME]
            _warn_misspelt(source, reader.line_num, [named[i] for i, h in enumerate(header) if h not in _BY_NAME])
            for name in dict.fromkeys(h for _, h in wanted):
                at = [f"{i + 1} ({named[i]})" for i, h in wanted if h == name]
                if len(at) > 1:  # two columns would fill one list (t and t_s are one column)
                    raise LogError(source, reader.line_num, f"expected each column once: {name} is in the header "
                                                            f"{len(at)} times (columns {', '.join(at)})")
        values: dict[str, list] = {h: [] for _, h in wanted}
        lines: list[int] = []
        for row in reader:
            line = reader.line_num
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) < len(header) or any(c.strip() for c in row[len(header):]):
                # a trailing separator (empty cells past the header) is fine; a value there
                # means the row's cells are shifted against the header
                raise LogError(source, line, f"expected {len(header)} cells (got {len(row)})")
            if delimiter == ";":
                row = _decimal_points(row)
            for i, h in wanted:
                cell = row[i]
                if columns is not None or _BY_NAME[h].kind == "text":
                    values[h].append(cell)
                    continue
                if merged and is_empty_cell(cell):
                    values[h].append(math.nan)
                    continue
                try:
                    v = float(cell)
                except ValueError:
                    raise LogError(source, line, f"column {h!r}: expected a number (got {cell!r})") from None
                if not math.isfinite(v) and not (h in NAN_COLUMNS and v != v):
                    raise LogError(source, line, f"column {h!r}: expected a finite number (got {cell!r})")
                values[h].append(v)
            lines.append(line)
    except csv.Error as exc:
        raise LogError(source, reader.line_num, f"expected valid CSV ({exc})") from None
    steps = None
    try:
        if columns is not None:
            values = columns.apply(values, len(lines), source, merged=merged)
        if merged:
            from simrunner.telemetry.sparse import SparseError, command_steps, merge_rows  # noqa: PLC0415 - merged logs only

            raw = {k: (tuple(v) if _BY_NAME[k].kind == "text" else np.asarray(v, dtype=float))
                   for k, v in values.items()}
            try:
                values, kept, notes = merge_rows(raw)
            except SparseError as exc:
                raise LogError(source, exc.row + 2, exc.message) from None  # mapped to its line below
            for note in notes:
                warnings.warn(f"{source}: {note}", LogWarning, stacklevel=3)
            lines = [lines[i] for i in kept]
            steps = command_steps(raw)
        repeats = None
        if repeated_stamps:
            values, lines, repeats = _drop_repeated_stamps(values, lines)
        log = replace(log_from_columns(values, source, CommandSteps(**steps) if steps is not None else None),
                      header_line=header_line)
        return log if repeats is None else _with_repeats(log, repeats)
    except LogError as exc:  # map the row index back to the file's line
        if exc.line >= 2 and exc.line - 2 < len(lines):
            raise LogError(source, lines[exc.line - 2], exc.message) from None
        raise


def _warn_misspelt(source: str, line: int, unread: list[str]) -> None:
    """Warn (:class:`LogWarning`) about header columns that are not read but look like a
    schema column misspelt (``spéed``, ``Speed_mps``): unknown columns are otherwise ignored."""
    import difflib

    names = list(COLUMN_NAMES) + list(FORMAT1_NAMES)
    for name in unread:
        close = difflib.get_close_matches(name.strip().lower(), names, n=1, cutoff=0.75)
        if close:
            want = FORMAT1_NAMES.get(close[0], close[0])
            warnings.warn(f"{source}:{line}: column {name!r} is not read: did you mean {want!r}? (columns "
                          "are read by their exact names, docs/telemetry.md)", LogWarning, stacklevel=4)


def _check_format_line(line: str, source: str, lineno: int) -> None:
    words = line.lstrip("#").split()
    if "format" in words:
        k = words.index("format")
        if k + 1 < len(words) and words[k + 1].isdigit() and int(words[k + 1]) > FORMAT_VERSION:
            raise LogError(source, lineno, f"log format {words[k + 1]} is newer than this "
                                           f"simulator reads (format {FORMAT_VERSION}): update nxpcup-sim")


# -- recording a run -------------------------------------------------------------------------
KEEP_ROWS = 1 << 17  # rows a RunRecorder keeps in memory (43 min at 50 fps); then every 2nd, 4th, ...
_N_RUN_COLUMNS = 13  # frame .. yaw_rate_cmd_radps, lap, off_track (coast is always 0)
LIFT_COLUMNS = ("z_m", "pitch_rad")  # a run on a track with hills records these too
ENCODER_COLUMNS = ("enc_fl", "enc_fr", "enc_rl", "enc_rr")  # a car with encoders: those of its wheels
IMU_COLUMNS = ("gyro_x_radps", "gyro_y_radps", "gyro_z_radps", "accel_x_mps2", "accel_y_mps2", "accel_z_mps2")
DUTY_COLUMNS = ("duty_left", "duty_right", "duty_cmd")
NAN_COLUMNS = frozenset({"duty_cmd"})  # nan: no such command in force (set_motors' own duties)  # a duty-commanded car: its rear motors' duties
EXTRA_COLUMNS = LIFT_COLUMNS + ENCODER_COLUMNS + IMU_COLUMNS + DUTY_COLUMNS  # only when a run has them


class RunRecorder:
    """Collects a run's rows (see the module docstring); :meth:`freeze` gives the RunLog.

    ``frame(...)`` at each camera frame boundary k appends the state of row k and closes row
    k - 1 with ``previous_command``: the command the first physics step after ``t_k-1``
    applied (None when no step followed). ``text(lines)`` adds ``add_data`` text to the open
    row. No row is changed after it is closed.

    Memory stays bounded: each closed row goes to ``sink`` (``sink.row(values, text)``, e.g.
    a :class:`simrunner.telemetry.stream.CsvStream` writing the CSV as the run goes) and is kept in
    memory only while fewer than ``max_rows`` are kept; then every other kept row is dropped
    and from there on only every 2nd (4th, ...) row is kept (``stride``). :meth:`freeze` gives
    the kept rows plus the open (last) row: every row of a run shorter than ``max_rows``
    frames, a thinned log (``stride`` > 1) of a longer one. :meth:`finish` closes the open
    row into the sink.

    ``extra``: the names of :data:`EXTRA_COLUMNS` this run records too, in schema order (the
    car's height and pitch on a track with hills, its encoders, its IMU): their values follow
    ``off_track`` in ``frame(..., *extra_values)``.
    """

    def __init__(self, *, record_text: bool = True, sink=None, max_rows: int = KEEP_ROWS,
                 extra: tuple[str, ...] = ()) -> None:
        if max_rows < 2:
            raise SimError(f"RunRecorder: max_rows = {max_rows!r}: expected >= 2")
        if tuple(extra) != tuple(n for n in EXTRA_COLUMNS if n in extra):
            raise SimError(f"RunRecorder: extra = {extra!r}: expected names of EXTRA_COLUMNS in their order")
        self.max_rows = int(max_rows)
        self.extra = tuple(extra)
        self._width = _N_RUN_COLUMNS + len(self.extra)
        self._rows = np.empty((min(1024, self.max_rows), self._width))
        self._kept = 0        # rows held in _rows
        self._closed = 0      # rows closed so far (written to the sink)
        self.stride = 1       # a closed row i is kept when i % stride == 0
        self._texts: dict[int, str] = {}  # position in _rows -> data_text
        self._open: tuple | None = None   # state of the open row
        self._open_text: list[str] = []
        self._open_command: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.record_text = record_text
        self.sink = sink

    def __len__(self) -> int:
        """Rows recorded so far (closed and open), kept in memory or not."""
        return self._closed + (self._open is not None)

    def frame(self, k: int, t_s: float, x_m: float, y_m: float, yaw_rad: float, speed_mps: float,
              steer_rad: float, yaw_rate_radps: float, command: tuple[float, float, float],
              previous_command: tuple[float, float, float] | None, lap: int, off_track: bool,
              *extra: float) -> None:
        """Row k: the state at ``t_s``; ``command`` is in force now (row k keeps it if no
        step follows); ``extra``: the values of the recorder's ``extra`` columns."""
        if self._open is not None:
            self._close(self._open_command if previous_command is None else previous_command)
        self._open = (k, t_s, x_m, y_m, yaw_rad, speed_mps, steer_rad, yaw_rate_radps, lap, off_track, *extra)
        self._open_command = command

    def _row(self, command: tuple[float, float, float]) -> tuple:
        s = self._open
        row = (s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], command[0], command[1], command[2],
               s[8], s[9])
        return row + s[10:] if self.extra else row

    def _close(self, command: tuple[float, float, float]) -> None:
        row = self._row(command)
        text = TEXT_SEPARATOR.join(self._open_text) if self._open_text else ""
        if self._open_text:
            self._open_text = []
        if self.sink is not None:
            self.sink.row(row, text)
        i = self._closed
        self._closed = i + 1
        if i % self.stride == 0:
            self._keep(row, text)

    def _keep(self, row: tuple, text: str) -> None:
        n = self._kept
        if n == len(self._rows):
            if n < self.max_rows:  # grow
                grown = np.empty((min(2 * n, self.max_rows), self._width))
                grown[:n] = self._rows[:n]
                self._rows = grown
            else:  # full: keep every other row, double the stride
                half = (n + 1) // 2
                self._rows[:half] = self._rows[:n:2]
                self._texts = {p // 2: v for p, v in self._texts.items() if p % 2 == 0}
                self._kept = n = half
                self.stride *= 2
                if (self._closed - 1) % self.stride:
                    return
        self._rows[n] = row
        if text:
            self._texts[n] = text
        self._kept = n + 1

    def text(self, lines: Sequence[str]) -> None:
        """``add_data`` text of the open row (lines added within one frame accumulate)."""
        if self.record_text and self._open is not None:
            self._open_text.extend(lines)

    def finish(self) -> None:
        """Close the open row into the sink (the end of the run; it keeps the command in
        force at its boundary). The rows stay available to :meth:`freeze`."""
        if self._open is not None and self.sink is not None:
            self.sink.row(self._row(self._open_command), TEXT_SEPARATOR.join(self._open_text))
            self.sink = None

    def freeze(self, source: str = "<run>") -> RunLog:
        """The log so far: the kept rows and the open (last) row, which keeps the command in
        force at its boundary (see the class docstring for long runs)."""
        n = self._kept
        rows = self._rows[:n]
        texts = [self._texts.get(i, "") for i in range(n)]
        if self._open is not None:
            last = np.array([self._row(self._open_command)], dtype=float)
            rows = np.concatenate((rows, last))
            texts.append(TEXT_SEPARATOR.join(self._open_text))
        m = len(rows)
        cols = {"frame": rows[:, 0], "t_s": rows[:, 1], "x_m": rows[:, 2], "y_m": rows[:, 3],
                "yaw_rad": rows[:, 4], "speed_mps": rows[:, 5], "steer_rad": rows[:, 6],
                "yaw_rate_radps": rows[:, 7], "speed_cmd_mps": rows[:, 8], "steer_cmd_rad": rows[:, 9],
                "yaw_rate_cmd_radps": rows[:, 10], "coast": np.zeros(m), "lap": rows[:, 11],
                "off_track": rows[:, 12], "data_text": tuple(texts)}
        cols.update({name: rows[:, 13 + i] for i, name in enumerate(self.extra)})
        return log_from_columns(cols, source)


def empty_log(source: str = "<run>") -> RunLog:
    """A log with no rows (every run column present)."""
    return RunRecorder().freeze(source)


def schema_markdown() -> str:
    """The schema table of docs/telemetry.md."""
    rows = ["| column | unit | meaning |", "| --- | --- | --- |"]
    rows += [f"| `{c.name}` | {c.unit} | {c.meaning} |" for c in COLUMNS]
    return "\n".join(rows)


__all__ = ["RunLog", "CommandSteps", "Repeats", "RunRecorder", "LogError", "LogWarning", "Column", "COLUMNS", "COLUMN_NAMES",
           "EXTRA_COLUMNS", "FORMAT_VERSION",
           "log_from_columns", "read_log", "write_log", "to_csv_text", "empty_log", "schema_markdown"]
