"""One batch worker: :class:`WorkerState` (the car and the tracks this worker has loaded)
and :func:`execute_job` (one run -> one row). Used by the local process pool
(:func:`worker_loop`, in a child process) and by the Ray actors alike.

A worker loads each track once and keeps the last :data:`MAX_TRACKS` (a ``SimTrack`` is
immutable and ``drive`` accepts it), so a run costs only the run. Each run still builds its
own car model, camera and judge (:class:`simrunner.run.runner.Run`) and executes the
controller file afresh: a run's row does not depend on what the worker ran before.
"""
from __future__ import annotations

import os
import sys
import time
import traceback
from collections import OrderedDict

from simrunner.errors import SimError
from simrunner.workflows.batch.results import failure_row, row_from_result
from simrunner.workflows.batch.spec import BatchConfig, Job, TrackRef

MAX_TRACKS = 16
"""Tracks a worker keeps loaded (least recently used dropped first)."""


class WorkerState:
    """What a worker keeps between runs: the batch config, the car and loaded tracks."""

    def __init__(self, config: BatchConfig):
        from vehicle.description import load_car

        self.config = config
        self.car = load_car(config.car)
        self.tracks: OrderedDict[str, object] = OrderedDict()
        self.loads = 0  # tracks loaded (for the overhead benchmark)

    def track(self, ref: TrackRef):
        """The loaded ``SimTrack`` of ``ref`` (raises ``SimError``/``TrackError`` once per
        attempt for a track that does not load)."""
        got = self.tracks.get(ref.label)
        if got is None:
            got = self.tracks[ref.label] = _load(ref, self.car)
            self.loads += 1
            while len(self.tracks) > MAX_TRACKS:
                self.tracks.popitem(last=False)
        else:
            self.tracks.move_to_end(ref.label)
        return got


def _load(ref: TrackRef, car):
    from simrunner.track import load_track

    if ref.random_seed is None:
        return load_track(ref.path, car=car)
    from simrunner.track import track_from_trackgen
    from trackgen import parse_layout
    from trackgen.build import check_buildable
    from trackgen.random import random_layout

    text = random_layout(ref.random_seed, car=car)
    checked = check_buildable(parse_layout(text, path=ref.label), car, meshes=False)
    return track_from_trackgen(checked.track, geometry=checked.geometry, source=ref.label)


def run_settings(job: Job, cfg: BatchConfig):
    """The :class:`~simrunner.run.settings.RunSettings` of ``job`` (as ``simrunner drive``'s:
    a time limit of None is filled in for the track by the run)."""
    from simrunner.run.settings import RunSettings

    return RunSettings(laps=cfg.laps, time_limit_s=cfg.time_limit_s, seed=job.seed,
                       dt_s=cfg.dt_s, wall_limit_s=cfg.wall_limit_s, params=dict(job.params),
                       off_track_wheels=cfg.off_track_wheels, event=cfg.event,
                       mcu_time=cfg.mcu_time, mcu_scale=cfg.mcu_scale)


def run_time_limit_s(job: Job, state: WorkerState) -> float | None:
    """The simulated-time limit ``job`` will run with (loading its track: drive's default
    depends on the lap length); None if the track does not load (the run reports it)."""
    if state.config.time_limit_s is not None:
        return float(state.config.time_limit_s)
    try:
        return float(run_settings(job, state.config).for_track(state.track(job.track)).time_limit_s)
    except Exception:  # noqa: BLE001 - execute_job reports it in the row
        return None


def execute_job(job: Job, state: WorkerState, outputs: dict[str, str] | None = None) -> dict:
    """Run ``job``; always returns a row (a fault that is not the controller's is outcome
    ``error`` with its message)."""
    from simrunner.run.runner import drive

    cfg = state.config
    t0 = time.perf_counter()
    try:
        track = state.track(job.track)
        settings = run_settings(job, cfg)
        outputs = outputs or {}
        result = drive(cfg.program or cfg.controller, track=track, car=state.car, settings=settings,
                       video=outputs.get("video"), csv=outputs.get("csv"))
    except Exception as exc:  # noqa: BLE001 - recorded in the row, the batch goes on
        from trackgen import TrackError
        from vehicle.description import CarDescriptionError

        if isinstance(exc, (SimError, TrackError, CarDescriptionError)):
            message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        else:
            last = traceback.format_exception_only(type(exc), exc)[-1].strip()
            message = f"internal error: {last}"
        return failure_row(job, cfg.laps, "error", message, round(time.perf_counter() - t0, 4))
    return row_from_result(job, result, track.centreline)


WARM_MODULES = ("simrunner.car.effects", "simrunner.run.runner", "simrunner.sensors.camera",
                "simrunner.sensors.imaging", "trackgen.build", "trackgen.closure", "simrunner.run.start",
                "simrunner.track.trace", "numpy.random", "manifold3d")
"""What every run imports (dartpy, OpenCV, NumPy's random generators, manifold3d for a layout's
raster; not numba: the camera's line is NumPy, :mod:`simrunner.sensors.line_row`)."""


def warm_up() -> None:
    """Import :data:`WARM_MODULES`, so a worker reports ready - and its first run's timeout
    starts - only when it can run at full speed (the local pool imports them once in the
    batch's process and forks its workers after, :mod:`.pool`)."""
    import importlib

    for name in WARM_MODULES:
        importlib.import_module(name)


def quiet_output() -> None:
    """Send this process's stdout/stderr (controllers' prints) to /dev/null: the parent
    shows a progress bar; a run's fault is in its row."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    for fd in (1, 2):
        os.dup2(devnull, fd)
    os.close(devnull)
    sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - for the life of the worker
    sys.stderr = sys.stdout


def worker_loop(conn, config: BatchConfig, quiet: bool = True, report: str | None = None,
                parent_pid: int | None = None) -> None:
    """A child process of the local pool: receive ``(job, outputs)``, send back the row;
    ``None`` ends it. ``report``: the file the hard watchdog writes its stack dump to when a
    run is stuck in one C-level call (:func:`death_row` reads it). ``parent_pid``: the pid of
    the process that started it (None: a forkserver did)."""
    from simrunner.run.supervise import Supervision, die_with_parent, supervised_by

    # a batch killed by SIGKILL takes its workers with it: a forked worker holds both ends of
    # its pipe, so it would never read an end of file and wait for work for ever
    die_with_parent(parent_pid)
    if quiet:
        quiet_output()
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    for sig in (signal.SIGTERM, signal.SIGHUP):   # (a forked worker has its parent's handlers)
        signal.signal(sig, signal.SIG_DFL)
    try:
        warm_up()
        state = WorkerState(config)
        dump = open(report if report else os.devnull, "w", errors="replace")  # noqa: SIM115 - for the life of the worker
    except Exception as exc:  # noqa: BLE001 - e.g. a bad car file: every run reports it
        conn.send(("fatal", f"{type(exc).__name__}: {exc}"))
        return
    conn.send(("ready", os.getpid()))
    with supervised_by(Supervision(dump, csv_path=None)):
        while True:
            try:
                msg = conn.recv()
            except EOFError:
                return
            if msg is None:
                return
            job, outputs = msg
            conn.send(("start", (job.index, run_time_limit_s(job, state))))  # for its timeout
            conn.send(("row", execute_job(job, state, outputs)))


def death_row(job: Job, config: BatchConfig, exitcode: int | None, report: str | os.PathLike,
              outputs: dict[str, str] | None = None) -> dict:
    """The row of ``job``, whose worker process ended during it with ``exitcode``, told as
    ``simrunner drive`` tells it: a controller stuck in one C-level call (the hard watchdog's
    stack dump in ``report``) is outcome ``stalled`` naming the controller's file:line; a fault
    in a C/C++ program's constructors as its library loaded (the in-process host's report in
    ``report``) or in a thread the program started (the same) is ``controller_error`` naming the
    fault's file:line; an exit, spinner_fail or a
    misused Spinner call there (the host's report; the worker ended with status 70) is told as
    drive tells it (:func:`~simrunner.run.postmortem.load_end`: ``controller_error``, or
    ``controller_returned`` for exit(0), naming the call's file:line); otherwise ``worker_died``
    naming the signal or exit code. Laps, lap times, simulated time and frames come from the
    run's CSV when one was asked for (``outputs``)."""
    from pathlib import Path

    from simrunner.run.postmortem import (dead_fault, killed_message, load_end, read_run_log, run_log_laps,
                                          stuck_location, stuck_message)

    try:
        dump = Path(report).read_text(errors="replace")
    except OSError:
        dump = ""
    csv = (outputs or {}).get("csv")
    log = read_run_log(Path(csv)) if csv else None
    if "Timeout (" in dump:  # faulthandler's header (simrunner.run.watchdog)
        outcome = "stalled"
        message = stuck_message(stuck_location(dump, config.controller), config.wall_limit_s)
    elif (fault := dead_fault(dump, config.controller)) is not None:
        outcome, message = "controller_error", str(fault)
    elif (ended := load_end(dump, config.controller)) is not None:
        outcome, message = str(ended.outcome), ended.message
    elif exitcode is not None and exitcode < 0:
        outcome, message = "worker_died", killed_message(-exitcode, log)
    else:
        outcome, message = "worker_died", f"worker process died during the run (exit code {exitcode})"
    row = failure_row(job, config.laps, outcome, message)
    if log is not None and len(log):
        laps_completed, lap_times = run_log_laps(log)
        row.update(laps_completed=laps_completed, lap_times_s=lap_times,
                   best_lap_s=min(lap_times) if lap_times else None,
                   sim_time_s=float(log.t_s[-1]), frames=len(log))
    return row


__all__ = ["WorkerState", "execute_job", "worker_loop", "warm_up", "WARM_MODULES", "death_row", "run_settings",
           "run_time_limit_s", "MAX_TRACKS"]
