"""``simrunner batch`` as a library function: :func:`run_batch`.

Checks every input in this process first (controller file, car, tracks, seeds, parameter
lists, output selection: one :class:`BatchError` line before any run), runs the jobs on the
local process pool or on Ray, re-runs the runs selected by ``video="failures"`` /
``csv="failures"`` with those outputs (runs are deterministic, so the re-run is the same
run; runs that timed out or whose worker died are not re-run), and writes ``results.csv``, ``results.json`` and ``summary.png`` to ``out_dir``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from simrunner.workflows.batch.pool import LocalBackend
from simrunner.workflows.batch.scheduler import WorkerTiming, default_workers, run_jobs
from simrunner.workflows.batch.results import (BATCH_OUTCOMES, PARAMS_READ, RESERVED, RUN_WARNINGS, PartialResults,
                                               deterministic, write_results)
from simrunner.workflows.batch.spec import (BatchConfig, BatchError, Job, make_jobs, parse_grid,
                                            parse_seeds, resolve_tracks)

OK_OUTCOMES = ("finished", "controller_returned")


def default_run_timeout_s(time_limit_s: float | None) -> float:
    """The wall-clock limit of a run with this simulated-time limit (s): 60 s + 4 x the limit
    (None, not known yet: drive's smallest default, 60 s)."""
    from simrunner.run.settings import DEFAULT_TIME_LIMIT_S

    return 60.0 + 4.0 * (DEFAULT_TIME_LIMIT_S if time_limit_s is None else time_limit_s)


@dataclass(frozen=True)
class Selection:
    """Which runs get an output: ``"none"``, ``"all"``, ``"failures"`` or run indices."""

    mode: str = "none"
    runs: frozenset[int] = frozenset()

    @classmethod
    def parse(cls, text: str | None, what: str) -> "Selection":
        t = (text or "none").strip().lower()
        if t in ("none", "all", "failures"):
            return cls(t)
        try:
            runs = frozenset(int(v) for v in t.split(","))
        except ValueError:
            raise BatchError(f"--{what} {text!r}: expected none, all, failures or run numbers "
                             "like 0,5,7") from None
        if any(r < 0 for r in runs):
            raise BatchError(f"--{what} {text!r}: run numbers are >= 0")
        return cls("runs", runs)

    def upfront(self, job: Job) -> bool:
        return self.mode == "all" or (self.mode == "runs" and job.index in self.runs)


@dataclass(frozen=True)
class BatchResult:
    """``rows`` sorted by run; the files written; ``rerun_mismatches``: re-run runs (for
    failure outputs) whose row differed from the first run's (expected: none);
    ``worker_timing``: the workers of the first pass (start-up and steady rates, for
    benchmarks)."""

    rows: list[dict]
    csv_path: Path
    json_path: Path
    plot_path: Path | None
    wall_time_s: float
    workers: int
    backend: str
    rerun_mismatches: tuple[int, ...] = ()
    worker_timing: tuple[WorkerTiming, ...] = ()
    params_read: tuple[str, ...] = ()  # the names the runs' controller read (spinner.param)
    unused_params: tuple[str, ...] = ()  # swept --param names no run read
    warnings: tuple[tuple[str, tuple[int, ...]], ...] = ()  # each run warning and the runs that gave it

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for row in self.rows:
            out[row["outcome"]] = out.get(row["outcome"], 0) + 1
        return out


def _program(controller: Path, build: dict):
    """The C/C++ program of ``controller`` (a source or .so) built with ``build`` (run_batch), or
    None for a Python controller; a ControllerFileError for a bad build."""
    if not any(build.values()) and controller.suffix == ".py":
        return None  # (a Python batch does not import the C build machinery: ~15 ms of start-up)
    from simrunner.run.native.build import build_firmware, is_native

    if not any(build.values()) and not is_native(controller):
        return None
    return build_firmware([str(controller), *map(str, build.get("sources", ()))],
                          include_dirs=build.get("include_dirs", ()), defines=build.get("defines", ()),
                          kit=build.get("kit"), isrs=build.get("isrs", ()))


def run_batch(controller: str | Path, *, out_dir: str | Path, tracks=(), seeds: str | int = 1,
              params=(), laps: int = 1, time_limit_s: float | None = None, dt_s: float = 0.002,
              wall_limit_s: float = 10.0, car: str | Path | None = None,
              workers: int | None = None, run_timeout_s: float | None = None,
              video: str | None = None, csv: str | None = None, plot: bool = True,
              ray: str | None = None, force: bool = False, start_method: str | None = None,
              on_row: Callable[[dict], None] | None = None,
              on_plan: Callable[[int], None] | None = None, quiet_workers: bool = True,
              off_track_wheels: int | None = None, event: str | None = None,
              mcu_time: str | float | None = None, mcu_scale: float = 1.0,
              build: dict | None = None) -> BatchResult:
    """Run ``controller`` over every (track, parameter combination, seed); see
    docs/batch.md. ``tracks``: files, folders, globs, ``random:N`` (default: the bundled
    track). ``seeds``: N (0..N-1) or ``"A:B"``. ``params``: ``["NAME=V1,V2", "K=1:2:0.5"]``.
    ``ray``: None (local pool), ``"local"`` (a local Ray cluster) or a cluster address.
    ``on_plan``: called once with the number of runs; ``on_row``: with each row as it arrives
    (a progress bar). ``time_limit_s``: of each run (default: ``simrunner drive``'s for the
    run's track, laps and event: ``max(60 s, laps x lap length / 0.5 m/s)``, an event's own,
    the race's 120 s); ``run_timeout_s``: wall-clock limit of a run (default 60 s + 4 x its
    time limit); ``off_track_wheels``, ``event``, ``mcu_time``, ``mcu_scale``: as for
    ``simrunner drive``. ``build``: a C/C++ program's build as ``simrunner drive`` takes it
    (``sources``: its other files, ``include_dirs``, ``defines``, ``kit``, ``isrs``: ``(name,
    period_s)``), built once here for every run."""
    from simrunner.run.controller import load_controller
    from simrunner.run.runner import default_track
    from simrunner.run.events import event_track
    from simrunner.run.rules import EVENTS
    from simrunner.run.settings import RunSettings
    from vehicle.description import load_car

    ctl_path = Path(controller).resolve()
    program = _program(ctl_path, build or {})      # a C/C++ program, built once; else None
    if program is None:
        load_controller(ctl_path)                   # a missing/broken file: one line, now
    load_car(car)
    if time_limit_s is None and event in EVENTS:
        time_limit_s = EVENTS[event].time_limit_s  # the discipline's (as drive)
    # else None: each run gets drive's default for its track (RunSettings.for_track)
    checked = RunSettings(laps=laps, time_limit_s=time_limit_s, dt_s=dt_s, wall_limit_s=wall_limit_s,
                          off_track_wheels=off_track_wheels, event=event, mcu_time=mcu_time,
                          mcu_scale=mcu_scale)
    mcu_time, mcu_scale = checked.mcu_time, checked.mcu_scale
    refs = resolve_tracks(list(tracks) or [str((event and event_track(event)) or default_track())])
    grid = parse_grid(list(params), reserved=RESERVED)
    jobs = make_jobs(refs, parse_seeds(seeds), grid)
    video_sel, csv_sel = Selection.parse(video, "video"), Selection.parse(csv, "csv")
    n_workers = default_workers() if workers is None else int(workers)
    if n_workers < 1:
        raise BatchError(f"--workers {workers}: expected >= 1")
    if run_timeout_s is not None:
        timeout = float(run_timeout_s)
        if not timeout > 0:
            raise BatchError(f"--run-timeout {run_timeout_s}: expected > 0 (s)")
    elif time_limit_s is not None:
        timeout = default_run_timeout_s(time_limit_s)
    else:   # each run's own limit, which its worker reports as the run starts
        timeout = default_run_timeout_s
    out = Path(out_dir)
    if (out / "results.csv").exists() and not force:
        raise BatchError(f"{out}: already holds results.csv (use --force to replace it)")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BatchError(f"{out}: cannot create the output folder ({exc.strerror or exc})") from None
    config = BatchConfig(controller=str(ctl_path), program=program,
                         car=None if car is None else str(Path(car).resolve()),
                         laps=laps, time_limit_s=time_limit_s, dt_s=dt_s, wall_limit_s=wall_limit_s,
                         off_track_wheels=off_track_wheels, event=event,
                         param_names=tuple(grid), mcu_time=mcu_time, mcu_scale=mcu_scale)

    def outputs_for(job: Job, video_on: bool, csv_on: bool) -> dict | None:
        if not (video_on or csv_on):
            return None
        runs = out / "runs"
        runs.mkdir(exist_ok=True)
        stem = runs / f"run_{job.index:05d}"
        paths = {k: stem.with_suffix(sfx) for k, sfx, on in
                 (("video", ".mp4", video_on), ("csv", ".csv", csv_on)) if on}
        for path in paths.values():  # an earlier batch's (--force, a killed one's): a run that
            path.unlink(missing_ok=True)  # dies before writing its own is not told from it
        return {k: str(v) for k, v in paths.items()}

    if ray is None:
        backend_name, make_backend = "local", lambda: LocalBackend(config, start_method=start_method,
                                                                    quiet=quiet_workers)
    else:
        from simrunner.workflows.batch.ray_backend import RayBackend

        backend_name = f"ray ({ray})"
        ray_backend = RayBackend(config, address=ray, workers=workers, quiet=quiet_workers)
        n_workers = ray_backend.workers
        make_backend = lambda: ray_backend  # noqa: E731

    rows: dict[int, dict] = {}
    if on_plan is not None:
        on_plan(len(jobs))

    partial = PartialResults(out / "results.partial.csv", tuple(grid))

    read: set[str] = set()
    reported = [False]  # a run that reported what it read (one that could not start has not)

    warned: dict[str, list[int]] = {}  # each run's warning (a clock read, a kit's set-up) -> runs

    def take(row: dict) -> None:
        if PARAMS_READ in row:
            read.update(row.pop(PARAMS_READ))
            reported[0] = True
        for text in row.pop(RUN_WARNINGS, ()):
            warned.setdefault(text, []).append(row["run"])
        rows[row["run"]] = row
        partial.add(row)  # on disk as it comes: a batch killed (kill -9, the OOM killer) keeps it
        if on_row is not None:
            on_row(row)

    t0 = time.perf_counter()
    mismatches: list[int] = []
    timing: list[WorkerTiming] = []
    try:
        lost: set[int] = set()   # runs whose worker died or was stopped: not re-run
        timing = run_jobs(jobs, make_backend(), workers=n_workers, run_timeout_s=timeout, laps=laps,
                          on_row=take, outputs=lambda j: outputs_for(j, video_sel.upfront(j),
                                                                      csv_sel.upfront(j)),
                          on_lost=lambda j: lost.add(j.index))
        again = [j for j in jobs if rows[j.index]["outcome"] not in OK_OUTCOMES + BATCH_OUTCOMES
                 and j.index not in lost
                 and (video_sel.mode == "failures" or csv_sel.mode == "failures")
                 and not (video_sel.upfront(j) and csv_sel.upfront(j))]
        if again:
            first = {j.index: rows[j.index] for j in again}

            def check(row: dict) -> None:
                row.pop(PARAMS_READ, None)
                row.pop(RUN_WARNINGS, None)
                if deterministic(row) != deterministic(first[row["run"]]):
                    mismatches.append(row["run"])

            run_jobs(again, make_backend(), workers=n_workers, run_timeout_s=timeout, laps=laps,
                     on_row=check, outputs=lambda j: outputs_for(
                         j, video_sel.mode == "failures" or video_sel.upfront(j),
                         csv_sel.mode == "failures" or csv_sel.upfront(j)))
    finally:
        if ray is not None:
            ray_backend.shutdown()
        ordered = [rows[i] for i in sorted(rows)]
        wall = time.perf_counter() - t0
        meta = {"controller": str(ctl_path), "car": config.car, "laps": laps,
                "time_limit_s": time_limit_s, "dt_s": dt_s, "wall_limit_s": wall_limit_s,
                "off_track_wheels": off_track_wheels, "event": event, "mcu_time": mcu_time,
                "mcu_scale": mcu_scale,
                "tracks": [r.label for r in refs], "seeds": parse_seeds(seeds),
                "params": {k: v for k, v in grid.items()}, "runs_planned": len(jobs),
                "runs_done": len(ordered), "backend": backend_name, "workers": n_workers,
                "wall_time_s": round(wall, 3),
                "warnings": [{"text": text, "runs": sorted(runs)} for text, runs in warned.items()]}
        csv_path, json_path = write_results(out, ordered, tuple(grid), meta)
        partial.remove()
    plot_path = None
    if plot and ordered:
        from simrunner.workflows.batch.plot import plot_summary

        plot_path = plot_summary(ordered, tuple(grid), out / "summary.png")
    return BatchResult(ordered, csv_path, json_path, plot_path, wall, n_workers, backend_name,
                       tuple(sorted(mismatches)), tuple(timing), tuple(sorted(read)),
                       tuple(sorted(set(grid) - read)) if reported[0] else (),
                       tuple((text, tuple(sorted(runs))) for text, runs in warned.items()))
