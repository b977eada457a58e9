"""The outputs of a run whose process the hard watchdog ended, written from what it left on
disk (:mod:`simrunner.run.supervise`): :func:`finish_stuck_run`; of one a signal killed:
:func:`finish_dead_run` (a fault in a C/C++ program's constructors as its library loaded into the
process, or in a thread the program started during its run, is named at its file:line from the
host's report, :func:`load_fault`, :func:`thread_fault`); of one a C/C++
program ended as its library loaded into the process (an exit, spinner_fail, a misused Spinner call
in a constructor: the process ends, status 70): :func:`finish_load_ended_run`, its outcome told as
with ``--isolate`` from the host's report (:func:`load_end`).

The run log holds every row closed before the stall (it streams one whole row per write).
From it: the summary (outcome ``stalled``; the message names the controller's file:line, read
from the watchdog's stack dump; laps and lap times from the log's ``lap`` column, to a camera
frame), the plot, and the video, rebuilt frame by frame from the rows: the camera view drawn
at each row's pose (without the camera noise), the API's numbers and the ``add_data`` text of
the row; ``add_data`` image lines are not in the log and are left out. The video the stuck
process was writing (``NAME.partial.mp4``, never closed, unplayable) is removed.
"""
from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

from simrunner.errors import ControllerError
from simrunner.run.native.symbolize import IN_CONSTRUCTOR
from simrunner.telemetry.log import TEXT_SEPARATOR, LogWarning, RunLog, empty_log, read_log, write_log
from simrunner.reports.outputs import Outputs, write_outputs
from simrunner.run.result import Outcome, RunResult

_FRAME = re.compile(r'^\s*File "(?P<file>.+)", line (?P<line>\d+) in (?P<func>.+)$')


@dataclass(frozen=True)
class StuckRun:
    """What the supervisor knows of the run it started: the command's inputs."""

    controller: str
    outputs: Outputs
    track: str | None = None
    car: str | None = None
    laps: int = 1
    seed: int = 0
    wall_limit_s: float = 10.0


def stuck_location(report: str, controller: str) -> str:
    """``file:line in function`` of the controller's innermost frame in a faulthandler dump
    (most recent call first), or ``""``."""
    want = Path(controller).resolve()
    for line in report.splitlines():
        m = _FRAME.match(line)
        if m and Path(m["file"]) == want:
            return f"{want.name}:{m['line']} in {m['func'].strip()}"
    return ""


def stuck_stack(report: str, controller: str) -> str:
    """The part of a faulthandler dump a controller's author reads: the stack of the thread
    the controller ran in, from the innermost call out to the controller's outermost frame
    (the simulator's frames under it left out), as a traceback's lines (most recent call
    first); the whole dump when no frame of ``controller`` is in it."""
    want = Path(controller).resolve()
    threads: list[list[str]] = []
    for line in report.splitlines():
        if line.startswith(("Thread ", "Current thread ")):
            threads.append([])
        elif threads and _FRAME.match(line):
            threads[-1].append(line)
    for frames in threads:
        mine = [i for i, line in enumerate(frames) if Path(_FRAME.match(line)["file"]) == want]
        if mine:
            return "\n".join(["the controller's stack (most recent call first):", *frames[:mine[-1] + 1]])
    return report.rstrip()


def stuck_message(where: str, wall_limit_s: float) -> str:
    """The outcome message of a run the hard watchdog ended (``where``: :func:`stuck_location`)."""
    hard_s = wall_limit_s + max(2.0, wall_limit_s)
    return (f"controller stuck in one C-level call{f' at {where}' if where else ''}: no Python "
            f"code ran for {hard_s:g} s of wall time (--wall-limit {wall_limit_s:g} s + "
            f"max(2 s, --wall-limit))")


def killed_message(signum: int, log: RunLog | None) -> str:
    """The outcome message of a run whose process signal ``signum`` killed (``log``: its run
    log so far, for the simulated time; None: no log was kept)."""
    import signal as signals

    try:
        name = signals.Signals(signum).name
    except ValueError:
        name = f"signal {signum}"
    why = ("kill -9, or the out-of-memory killer" if signum == signals.SIGKILL else
           "a crash the simulator could not catch: a C controller that ignored the signal, or crashed "
           "in a constructor or a library it loaded")
    at = "" if log is None else f" at t = {float(log.t_s[-1]):.3f} s" if len(log) else " before the first frame"
    return f"the run's process was killed by {name}{at} ({why})"


AT_LOAD = f"{IN_CONSTRUCTOR}, before the first frame"
"""Where a C/C++ program's fault or end at its library's load was (its constructors run then, before
the run's first frame)."""


def load_fault(report: str, controller: str) -> ControllerError | None:
    """The fault of a C/C++ program's constructors (a C++ global object's) as its library was
    loaded into the run's process, which died of it (:mod:`simrunner.run.native.inproc`), from the
    in-process host's report in ``report`` (the supervision's report file): a ``ControllerError``
    whose message names the fault's file:line and function, with the C backtrace; None when
    ``report`` holds no such report."""
    from simrunner.run.native.symbolize import load_fault_report

    return _described(load_fault_report(report), controller, f", {AT_LOAD}: it killed the run's process (the "
                      "program's library is loaded into the simulator's process before the run, where such a "
                      "fault cannot be caught; --isolate runs the program in a process of its own)")


def thread_fault(report: str, controller: str) -> ControllerError | None:
    """The fault of a thread a C/C++ program started itself (pthread_create, std::thread; not
    main()'s) during its run in the run's process, which died of it (nothing can end the run from
    that thread and go on: :mod:`simrunner.run.native.inproc`), from the in-process host's report in
    ``report`` (the supervision's report file): a ``ControllerError`` whose message names the
    thread's file:line and function ('t.c:5: SIGSEGV: segmentation fault (in worker()), in a thread
    of the program's own (not main()'s): it killed the run's process (...)'), with the C backtrace;
    None when ``report`` holds no such report."""
    from simrunner.run.native.symbolize import STRAY, thread_fault_report

    found = thread_fault_report(report)
    if found is not None and found[2].startswith(STRAY):  # a thread an earlier run's program left running
        return _described((found[0], found[1], found[2][len(STRAY):]), controller, ": a thread an earlier run's "
                          "program in this process left running (not waited for), which killed this run's process "
                          "(join the program's threads before main() returns; --isolate runs the program in a "
                          "process of its own)")
    return _described(found, controller, ": it killed the run's process (the program runs "
                      "in the simulator's process, where a fault of its threads cannot be caught; --isolate runs "
                      "the program in a process of its own)")


def _described(found, controller: str, tail: str) -> ControllerError | None:
    """``found`` (a host report: library, host, text; or None) as a ``ControllerError`` naming
    the fault's file:line and function, then ``tail``, with the C backtrace."""
    from simrunner.run.native.symbolize import describe_fault

    if found is None:
        return None
    library, host, text = found
    line, traceback_text = describe_fault(text, {library}, host, Path(controller).stem)
    return ControllerError(line + tail, traceback_text)


def dead_fault(report: str, controller: str) -> ControllerError | None:
    """The C/C++ program's fault the in-process host reported in ``report`` before the run's
    process died of it: in a constructor as its library loaded (:func:`load_fault`) or in a thread
    of its own (:func:`thread_fault`); None when there is none."""
    return load_fault(report, controller) or thread_fault(report, controller)


LOAD_END_STATUS = 70
"""The exit status of a process whose C/C++ program ended in its constructors as its library loaded
(the in-process host's ``load_ended``)."""


@dataclass(frozen=True)
class LoadEnd:
    """How a C/C++ program ended in its constructors as its library loaded into the run's process
    (:func:`load_end`): the run's ``outcome``, its ``message`` and ``error`` (None for an exit with
    status 0: ``controller_returned``, as a return from main)."""

    outcome: Outcome
    message: str
    error: ControllerError | None


def load_end(report: str, controller: str) -> LoadEnd | None:
    """The end of a C/C++ program in its constructors (a C++ global object's) as its library was
    loaded into the run's process, which ended with it (status 70; nothing returns out of the
    loader, :mod:`simrunner.run.native.inproc`), told as ``--isolate`` tells it (there its
    constructors run in the run's own process) with where it was: ``exit(3)`` is ``controller_error``
    'the controller called exit(3) at c.c:4, in a constructor ...' (exit(0) ``controller_returned``),
    ``spinner_fail`` and a misused Spinner call ``controller_error`` naming its file:line, with the C
    backtrace; from the in-process host's report in ``report`` (the supervision's report file). None
    when ``report`` holds no such report."""
    from simrunner.run.native.symbolize import describe_fault, load_end_report, parse_report

    found = load_end_report(report)
    if found is None:
        return None
    library, host, text = found
    first, _, rest = text.partition("\n")
    key, name, status = (first.split(" ") + ["", ""])[:3]
    if key == "exit" and status.lstrip("-").isdigit():  # exit, _exit, _Exit, quick_exit
        location = parse_report(rest, {library}, host).location
        at = f" at {location.file}:{location.line}" if location is not None else ""
        message = f"the controller called {name}({int(status)}){at}, {AT_LOAD}"
        if int(status) & 0xFF == 0:  # (the status the process would end with, as isolated)
            return LoadEnd(Outcome.CONTROLLER_RETURNED, message, None)
        return LoadEnd(Outcome.CONTROLLER_ERROR, message, ControllerError(message, message + "\n"))
    line, traceback_text = describe_fault(text, {library}, host, Path(controller).stem)
    message = f"{line}, {AT_LOAD}"
    return LoadEnd(Outcome.CONTROLLER_ERROR, message, ControllerError(message, traceback_text))


def finish_stuck_run(run: StuckRun, report: str, csv_path: Path, *, wall_time_s: float,
                     cpu_time_s: float) -> RunResult:
    """Write the outputs of a run ended by the hard watchdog (see the module docstring);
    the result names them in ``outputs``. Raises the first output's ``SimError`` after the
    others were written, as :func:`~simrunner.reports.outputs.write_outputs`."""
    log = read_run_log(csv_path)
    message = (stuck_message(stuck_location(report, run.controller), run.wall_limit_s)
               + "; the outputs were written from the run log")
    return _finish(run, Outcome.STALLED, message, log, csv_path, wall_time_s, cpu_time_s)


def finish_dead_run(run: StuckRun, signum: int, csv_path: Path, *, wall_time_s: float,
                    cpu_time_s: float, report: str = "") -> RunResult:
    """Write the outputs of a run whose process a signal killed (module docstring of
    :mod:`simrunner.run.supervise`): outcome ``controller_error`` naming the signal, or, when
    ``report`` (the supervision's report file) holds the report of a fault in the program's
    constructors as it loaded or in a thread of its own (:func:`dead_fault`), naming its file:line
    (``error``: with its C backtrace)."""
    log = read_run_log(csv_path)
    error = dead_fault(report, run.controller) if report else None
    message = (str(error) if error is not None else killed_message(signum, log)) \
        + "; the outputs were written from the run log"
    return _finish(run, Outcome.CONTROLLER_ERROR, message, log, csv_path, wall_time_s, cpu_time_s, error)


def finish_load_ended_run(run: StuckRun, ended: LoadEnd, csv_path: Path, *, wall_time_s: float,
                          cpu_time_s: float) -> RunResult:
    """Write the outputs of a run whose C/C++ program ended in its constructors as its library
    loaded (``ended``: :func:`load_end`), before the first frame: the summary with its outcome and
    message, the plot, the CSV's header."""
    return _finish(run, ended.outcome, ended.message, read_run_log(csv_path), csv_path, wall_time_s,
                   cpu_time_s, ended.error)


def _finish(run: StuckRun, outcome: Outcome, message: str, log: RunLog, csv_path: Path,
            wall_time_s: float, cpu_time_s: float, error: ControllerError | None = None) -> RunResult:
    """The result of a run that ``log`` is all that is left of, its outputs written: the
    asked-for CSV too when the run ended before its first row was streamed (the columns'
    header, as a run that recorded nothing writes)."""
    from simrunner.run.runner import resolve_track
    from simrunner.run.settings import RunSettings
    from vehicle.description import load_car

    car = load_car(run.car)
    track, label = resolve_track(run.track, car)
    laps_completed, lap_times = run_log_laps(log)
    settings = RunSettings(laps=run.laps, seed=run.seed).for_track(track)
    result = RunResult(outcome=outcome, laps=settings.laps, laps_completed=laps_completed,
                       lap_times_s=lap_times, sim_time_s=float(log.t_s[-1]) if len(log) else 0.0,
                       wall_time_s=wall_time_s, cpu_time_s=cpu_time_s, track=label,
                       seed=run.seed, message=message, log=log, frames=len(log), error=error)
    if run.outputs.csv is not None:
        if not Path(run.outputs.csv).exists():
            write_log(log, run.outputs.csv)
        result.outputs["csv"] = str(run.outputs.csv)
    video = None
    if run.outputs.video is not None:
        video = _rebuild_video(log, run.outputs.video, track, car, settings.laps, run.outputs.video_fps)
    write_outputs(result, Outputs(plot=run.outputs.plot, summary=run.outputs.summary), video, track)
    return result


def read_run_log(csv_path: Path) -> RunLog:
    if not csv_path.exists():  # the run stalled before its first frame
        return empty_log(str(csv_path))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LogWarning)  # a row cut short is left out
        return read_log(csv_path)


def run_log_laps(log: RunLog) -> tuple[int, list[float]]:
    """Laps completed and their times, from the ``lap`` column (to a frame): a lap's time
    runs from the previous completion (the first: from the log's first row)."""
    if not len(log):
        return 0, []
    lap = log.lap.tolist()
    ends = [float(log.t_s[i]) for i in range(1, len(lap)) if lap[i] > lap[i - 1]]
    starts = [float(log.t_s[0])] + ends[:-1]
    return int(lap[-1]), [e - s for s, e in zip(starts, ends)]


def _rebuild_video(log: RunLog, path, track, car, laps: int, max_fps: float | None = None):
    """A VideoRecorder fed with every row of ``log`` (closed by write_outputs)."""
    from pieces.pose import Pose2
    from simrunner.reports.video import VideoRecorder
    from simrunner.sensors.camera import Camera

    path = Path(path)
    path.with_name(path.stem + ".partial.mp4").unlink(missing_ok=True)  # the stuck run's
    camera = Camera(car.camera, track)
    video = VideoRecorder(path, camera_fps=1.0 / car.camera.frame_period_s(), render=camera.render,
                          **({} if max_fps is None else {"max_fps": max_fps}),
                          raster=track.raster, laps=laps, line_row=car.camera.default_row,
                          car_length_m=car.chassis.wheelbase_m + 0.05, car_width_m=car.chassis.track_m)
    texts = log.data_text or ("",) * len(log)
    for i in range(len(log)):
        video.frame_boundary(int(log.frame[i]), float(log.t_s[i]),
                             Pose2(float(log.x_m[i]), float(log.y_m[i]), float(log.yaw_rad[i])), {
                                 "speed": float(log.speed_mps[i]), "steer": float(log.steer_rad[i]),
                                 "speed_cmd": float(log.speed_cmd_mps[i]),
                                 "steer_cmd": float(log.steer_cmd_rad[i]),
                                 "lap": int(log.lap[i]), "off_track": bool(log.off_track[i])})
        if texts[i]:
            video.add_text(texts[i].split(TEXT_SEPARATOR))
    return video


__all__ = ["AT_LOAD", "IN_CONSTRUCTOR", "LOAD_END_STATUS", "LoadEnd", "StuckRun", "dead_fault", "finish_stuck_run", "finish_dead_run",
           "finish_load_ended_run", "killed_message", "load_end", "load_fault", "read_run_log",
           "run_log_laps", "stuck_location", "stuck_message", "stuck_stack", "thread_fault"]
