"""Batch result rows and the files they go to: ``results.csv`` and ``results.json``.

One row per run (a plain dict, column order :func:`columns`):

    run, track, seed, <one column per --param>, outcome, message, laps, laps_completed,
    lap_times_s, best_lap_s, sim_time_s, frames, off_x_m, off_y_m, off_t_s, off_progress_m,
    off_progress_frac, wall_time_s, cpu_time_s

``off_*``: where the car left the road (outcome ``off_track``; empty otherwise): world
position (m), simulated time (s) and the distance along the centreline from the start pose
to the nearest centreline point (m; ``_frac`` of the lap). Batch-level outcomes besides
``simrunner drive``'s: ``error`` (the run could not start, e.g. a track that does not load),
``wall_timeout`` (the run passed ``--run-timeout`` of wall time: its worker was stopped) and
``worker_died`` (the worker process ended during the run, e.g. a crash in native code).

Every column except :data:`NONDETERMINISTIC` (wall-clock and CPU time) is bit-identical
whatever the number of workers, their order or the backend (local pool or Ray): floats are
written with ``repr`` (shortest exact), lists as space-separated ``repr``.
"""
from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from simrunner.workflows.batch.spec import Job
from vehicle.userfiles import write_atomic

FIXED_BEFORE = ("run", "track", "seed")
FIXED_AFTER = ("outcome", "message", "laps", "laps_completed", "lap_times_s", "best_lap_s",
               "passed", "penalty_s", "time_s", "sim_time_s", "frames", "off_x_m", "off_y_m", "off_t_s", "off_progress_m",
               "off_progress_frac")
NONDETERMINISTIC = ("wall_time_s", "cpu_time_s")
RESERVED = FIXED_BEFORE + FIXED_AFTER + NONDETERMINISTIC
BATCH_OUTCOMES = ("error", "wall_timeout", "worker_died")
#: the key of a row from a worker holding the --param names its run read (not written)
PARAMS_READ = "_params_read"
#: the key of a row from a worker holding its run's warnings (not a column: the batch's warnings)
RUN_WARNINGS = "_warnings"
FORMAT = 1


def columns(param_names: tuple[str, ...] | list[str]) -> list[str]:
    return [*FIXED_BEFORE, *param_names, *FIXED_AFTER, *NONDETERMINISTIC]


def base_row(job: Job, laps: int) -> dict[str, Any]:
    row: dict[str, Any] = {"run": job.index, "track": job.track.label, "seed": job.seed}
    row.update(dict(job.params))
    row.update({"outcome": "", "message": "", "laps": laps, "laps_completed": 0, "lap_times_s": [],
                "best_lap_s": None, "passed": False, "penalty_s": 0.0, "time_s": None, "sim_time_s": 0.0, "frames": 0, "off_x_m": None,
                "off_y_m": None, "off_t_s": None, "off_progress_m": None,
                "off_progress_frac": None, "wall_time_s": 0.0, "cpu_time_s": 0.0})
    return row


def failure_row(job: Job, laps: int, outcome: str, message: str, wall_time_s: float = 0.0) -> dict:
    row = base_row(job, laps)
    row.update(outcome=outcome, message=message, wall_time_s=wall_time_s)
    return row


def progress_along(centreline: np.ndarray | None, x_m: float, y_m: float) -> tuple[float, float] | None:
    """Distance (m) along a closed ``(N, 2)`` centreline to its point nearest ``(x, y)``,
    and that distance as a fraction of the loop; None without a centreline."""
    if centreline is None or len(centreline) < 2:
        return None
    pts = np.vstack([centreline, centreline[:1]])
    seg = np.hypot(*np.diff(pts, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    i = int(np.argmin(np.hypot(centreline[:, 0] - x_m, centreline[:, 1] - y_m)))
    total = float(cum[-1])
    return float(cum[i]), (float(cum[i]) / total if total > 0 else 0.0)


def row_from_result(job: Job, result, centreline: np.ndarray | None) -> dict[str, Any]:
    """A row from a :class:`simrunner.run.result.RunResult`."""
    row = base_row(job, result.laps)
    laps = [float(t) for t in result.lap_times_s]
    row.update(outcome=str(result.outcome), message=result.message,
               laps_completed=int(result.laps_completed), lap_times_s=laps,
               best_lap_s=min(laps) if laps else None, passed=bool(result.passed),
               penalty_s=float(result.penalty_s), time_s=result.time_s, sim_time_s=float(result.sim_time_s),
               frames=len(result.log), wall_time_s=round(float(result.wall_time_s), 4),
               cpu_time_s=round(float(result.cpu_time_s), 4))
    row[PARAMS_READ] = list(result.params_read)  # not a column: run_batch takes it out
    row[RUN_WARNINGS] = list(result.warnings)     # (the same)
    log = result.log
    if str(result.outcome) in ("off_track", "off_course") and len(log) and log.x_m is not None:
        x, y, t = float(log.x_m[-1]), float(log.y_m[-1]), float(log.t_s[-1])
        row.update(off_x_m=x, off_y_m=y, off_t_s=t)
        if result.course_from_start_m is not None and result.course_length_m:
            # the judge's place along the course (the right branch at a crossing)
            where = (result.course_from_start_m, result.course_from_start_m / result.course_length_m)
        else:
            where = progress_along(centreline, x, y)
        if where is not None:
            row.update(off_progress_m=where[0], off_progress_frac=where[1])
    return row


def deterministic(row: dict[str, Any]) -> dict[str, Any]:
    """The row without the wall-clock columns (what must match across worker counts)."""
    return {k: v for k, v in row.items() if k not in NONDETERMINISTIC}


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return " ".join(_cell(v) for v in value)
    return str(value)


def csv_text(rows: list[dict[str, Any]], param_names) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    cols = columns(param_names)
    writer.writerow(cols)
    for row in rows:
        writer.writerow([_cell(row.get(c)) for c in cols])
    return buf.getvalue()


def _json_safe(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, list):
        return [_json_safe(v) for v in value]
    return value


class PartialResults:
    """``results.partial.csv``: each row appended (and flushed) as its run finishes, in that
    order, so a batch killed before it writes ``results.csv`` keeps its finished runs;
    :meth:`remove` once the sorted files are written."""

    def __init__(self, path: Path, param_names):
        self.path = Path(path)
        self.param_names = tuple(param_names)
        self._file = None

    def add(self, row: dict[str, Any]) -> None:
        try:
            if self._file is None:
                self._file = open(self.path, "w", encoding="utf-8", newline="")  # noqa: SIM115 - kept open
                self._file.write(csv_text([], self.param_names))
            self._file.write(csv_text([row], self.param_names).split("\n", 1)[1])
            self._file.flush()
        except OSError:  # the final results.csv says what could not be kept here
            self._file = None

    def remove(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
        try:
            self.path.unlink()
        except OSError:
            pass


def write_results(out_dir: Path, rows: list[dict[str, Any]], param_names, meta: dict) -> tuple[Path, Path]:
    """Write ``results.csv`` and ``results.json`` (each atomically); rows sorted by run."""
    rows = sorted(rows, key=lambda r: r["run"])
    csv_path, json_path = out_dir / "results.csv", out_dir / "results.json"
    write_atomic(csv_path, csv_text(rows, param_names))
    doc = {"format": FORMAT, **meta, "columns": columns(param_names),
           "nondeterministic_columns": list(NONDETERMINISTIC),
           "runs": [{k: _json_safe(row.get(k)) for k in columns(param_names)} for row in rows]}
    write_atomic(json_path, json.dumps(doc, indent=1) + "\n")
    return csv_path, json_path


def read_results(path: str | Path) -> list[dict[str, Any]]:
    """The rows of a ``results.json``."""
    return json.loads(Path(path).read_text(encoding="utf-8"))["runs"]
