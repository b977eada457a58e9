"""Run a controller's ``main(spinner)`` against the simulated car: :func:`drive`.

One thread: the controller runs in the calling (main) thread; the simulation advances
inside its Spinner calls (:mod:`simrunner.run.clock`). At every camera frame the runner judges
(laps, off track), logs a telemetry row and hands the frame to the video writer thread.

The run ends when the judge counts the laps (``finished``), a wheel leaves the road
(``off_track``), the simulated time limit passes (``timeout``) — then the next Spinner call
raises :class:`~simrunner.errors.RunFinished` — when ``main`` returns
(``controller_returned``), when it raises (``controller_error``; also bad commands such as
NaN), or when it spends ``wall_limit_s`` of wall time without letting simulated time pass
(``stalled``: a SIGALRM watchdog, main thread only), or on Ctrl-C (``interrupted``).
Telemetry, video, plot and summary are written in every case.
"""
from __future__ import annotations

import gc
import inspect
import json
import math
import os
import signal
import sys
import threading
import time
import traceback
import types
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from vehicle.description import CarDescription, CarDescriptionError, load_car

from simrunner.run.clock import LockstepClock
from simrunner.errors import (ControllerError, ControllerFileError, RunFinished, SimError, Stalled)
from simrunner.run.spinner import Session, Spinner
from simrunner.run.log import TelemetryLog

OUTCOMES = ("finished", "off_track", "timeout", "controller_error", "controller_returned",
            "stalled", "interrupted")
SUCCESS_OUTCOMES = ("finished", "controller_returned")
_PACKAGE_DIR = str(Path(__file__).resolve().parent.parent)  # simrunner/: its frames are not the user's
_DATA_DIR = Path(__file__).resolve().parent.parent / "data"
DEFAULT_TRACK_NAME = "thesis_figure8.txt"


def default_track() -> Path:
    """The bundled default track layout (the thesis's figure-8, Fig. 4.2)."""
    return _DATA_DIR / DEFAULT_TRACK_NAME


@dataclass
class RunResult:
    """What a run did. ``outcome`` is one of :data:`OUTCOMES`; times in seconds."""

    outcome: str
    laps: int
    laps_completed: int
    lap_times_s: list[float]
    sim_time_s: float
    wall_time_s: float
    real_time_factor: float
    track: str
    seed: int
    message: str = ""
    cpu_time_s: float = 0.0  # process CPU time of the run loop (load-independent speed)
    error: ControllerError | None = None
    telemetry: TelemetryLog = field(default_factory=TelemetryLog, repr=False)
    outputs: dict[str, str] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.outcome in SUCCESS_OUTCOMES

    def summary(self) -> dict[str, Any]:
        """The ``--summary`` JSON object."""
        return {"outcome": self.outcome, "message": self.message, "laps": self.laps,
                "laps_completed": self.laps_completed,
                "lap_times_s": [round(t, 6) for t in self.lap_times_s],
                "sim_time_s": round(self.sim_time_s, 6), "wall_time_s": round(self.wall_time_s, 3),
                "real_time_factor": round(self.real_time_factor, 2),
                "cpu_time_s": round(self.cpu_time_s, 3), "track": self.track,
                "seed": self.seed, "frames": len(self.telemetry), "outputs": self.outputs}


# -- controller file ----------------------------------------------------------------------
def compile_controller(path: str | Path) -> types.CodeType:
    """Compile a controller file; bad files raise :class:`ControllerFileError` (one line)."""
    path = Path(path)
    if not path.is_file():
        raise ControllerFileError(f"{path}: no such controller file")
    if path.suffix != ".py":
        raise ControllerFileError(f"{path}: expected a Python file (.py) with main(spinner)")
    from vehicle.userfiles import read_user_text

    source = read_user_text(path, "controller", ControllerFileError, "Python")
    try:
        return compile(source, str(path.resolve()), "exec")
    except SyntaxError as exc:
        raise ControllerFileError(f"{path}:{exc.lineno}: syntax error: {exc.msg}") from None
    except ValueError as exc:  # e.g. null bytes
        raise ControllerFileError(f"{path}: not a Python file ({exc})") from None


def _controller_main(module: types.ModuleType, path: Path) -> Callable:
    main = getattr(module, "main", None)
    if not callable(main):
        raise ControllerFileError(f"{path}: no main(spinner) function defined")
    try:
        inspect.signature(main).bind(object())
    except TypeError:
        raise ControllerFileError(f"{path}: main must take one argument (the Spinner)") from None
    except ValueError:  # no signature (builtins): let the call decide
        pass
    return main


def user_traceback(exc: BaseException) -> str:
    """Traceback text of ``exc`` without the simulator's frames (the user's frames only)."""
    te = traceback.TracebackException.from_exception(exc)
    seen = set()

    def trim(t: traceback.TracebackException | None) -> None:
        while t is not None and id(t) not in seen:
            seen.add(id(t))
            t.stack = traceback.StackSummary.from_list(
                [f for f in t.stack if not f.filename.startswith(_PACKAGE_DIR)
                 and not f.filename.startswith("<frozen importlib")])
            trim(t.__cause__)
            t = t.__context__

    trim(te)
    return "".join(te.format())


# -- watchdog -----------------------------------------------------------------------------
class _Watchdog:
    """SIGALRM every ``period`` s: if the clock made no progress for ``limit_s`` of wall
    time, end the run and raise :class:`Stalled` in the controller (main thread only)."""

    def __init__(self, clock: LockstepClock, limit_s: float, user_file: str | None):
        self.clock = clock
        self.limit_s = float(limit_s)
        self.user_file = user_file
        self.period_s = min(0.25, self.limit_s / 4.0)
        self.armed = False
        self._old = None
        self.enabled = threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer")

    def _where(self, frame) -> str:
        f = frame
        while f is not None:
            if self.user_file and f.f_code.co_filename == self.user_file:
                return f" (at {Path(f.f_code.co_filename).name}:{f.f_lineno} in {f.f_code.co_name})"
            f = f.f_back
        return ""

    def _handler(self, signum, frame) -> None:
        if not self.armed:
            return
        idle = time.monotonic() - self.clock.last_progress_wall_s
        if idle <= self.limit_s:
            return
        msg = (f"controller stalled: {idle:.1f} s of wall time without letting simulated time "
               f"pass{self._where(frame)}; call get_image(), sleep() or get_time() in every loop "
               f"(limit --wall-limit {self.limit_s:g} s)")
        self.clock.finish("stalled", msg)
        self.clock.last_progress_wall_s = time.monotonic()  # raise again only after another limit
        raise Stalled(msg)

    def __enter__(self) -> "_Watchdog":
        if self.enabled:
            self._old = signal.signal(signal.SIGALRM, self._handler)
            signal.setitimer(signal.ITIMER_REAL, self.period_s, self.period_s)
        self.armed = True
        return self

    def disarm(self) -> None:
        self.armed = False
        if self.enabled and self._old is not None:
            signal.setitimer(signal.ITIMER_REAL, 0.0, 0.0)
            signal.signal(signal.SIGALRM, self._old)
            self._old = None

    def __exit__(self, *exc) -> None:
        self.disarm()


# -- per-frame work -----------------------------------------------------------------------
class _FrameWork:
    """``on_frame``: judge, telemetry row, video frame, end conditions."""

    def __init__(self, sim, judge, log: TelemetryLog, time_limit_s: float, video=None):
        self.sim, self.judge, self.log, self.video = sim, judge, log, video
        self.time_limit_s = time_limit_s
        self.clock: LockstepClock | None = None
        self.events: list = []
        # contact points as a list of (x, y) (CarSim.wheel_contacts) where the sim has it
        self._contacts = getattr(sim, "wheel_contacts", None) or sim.wheel_contacts_xy
        self._append = log.rows.append
        self._row_command = None  # the command tuple recorded in the last row

    def __call__(self, k: int) -> None:
        # (runs every camera frame)
        sim, judge, clock = self.sim, self.judge, self.clock
        t = clock.time_s
        pose = clock.pose()
        events = judge.update(t, pose, self._contacts())
        if events:
            self.events.extend(events)
        off = judge.off_track
        lap = judge.laps_completed
        cmd = self._row_command = clock.current_command
        speed, steer = sim.speed_mps, sim.steer_rad
        self._append((k, t, pose.x_m, pose.y_m, pose.yaw_rad, speed, steer, sim.yaw_rate_radps,
                      *cmd, lap, 1 if off else 0))
        if self.video is not None:
            self.video.frame_boundary(k, t, pose, {
                "speed": speed, "steer": steer, "speed_cmd": cmd[0], "steer_cmd": cmd[1],
                "lap": lap, "off_track": off})
        if lap >= judge.laps:
            clock.finish("finished", f"{lap} lap(s) completed")
        elif off:
            clock.finish("off_track", f"off track at t = {t:.3f} s (wheel(s) "
                                      f"{', '.join(judge.off_wheels)} off the road)")
        elif t >= self.time_limit_s - 1e-9:
            clock.finish("timeout", f"time limit of {self.time_limit_s:g} s simulated time reached")

    def command_applied(self, k: int, command: tuple[float, float, float]) -> None:
        """``on_row_command``: row k records the command the controller set at t_k (in force
        from t_k to the next change), not the one in force before t_k (docs/telemetry.md)."""
        if command is self._row_command:  # the clock's tuple is replaced at every command
            return
        rows = self.log.rows
        row = rows[-1]
        if row[0] == k and row[8:11] != command:
            rows[-1] = row[:8] + tuple(command) + row[11:]


# -- tracks -------------------------------------------------------------------------------
_TRACK_CACHE: dict = {}


def _load_track(spec: str | Path, car: CarDescription):
    """``simrunner.track.load.load_track`` with a small per-process cache (SimTrack is immutable)."""
    from simrunner.track.load import load_track

    path = Path(spec)
    if not path.exists():
        raise SimError(f"{path}: no such track (expected a layout .txt, a trackgen folder, a "
                       f"world file or a Gazebo model folder)")
    key = (str(path.resolve()), path.stat().st_mtime_ns, car)
    if key not in _TRACK_CACHE:
        if len(_TRACK_CACHE) >= 4:
            _TRACK_CACHE.pop(next(iter(_TRACK_CACHE)))
        _TRACK_CACHE[key] = load_track(path, car=car)
    return _TRACK_CACHE[key]


# -- drive ----------------------------------------------------------------------------------
def _check_options(laps, time_limit_s, seed, dt_s, wall_limit_s) -> None:
    if isinstance(laps, bool) or not isinstance(laps, (int, np.integer)) or laps < 1:
        raise SimError(f"laps = {laps!r}: expected a whole number >= 1")
    for name, v, lo, hi in (("time_limit_s", time_limit_s, 0.0, 1e6), ("dt_s", dt_s, 0.0, 0.02),
                            ("wall_limit_s", wall_limit_s, 0.0, 1e6)):
        if not isinstance(v, (int, float)) or not math.isfinite(v) or not lo < v <= hi:
            raise SimError(f"{name} = {v!r}: expected a number in ({lo:g}, {hi:g}]")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SimError(f"seed = {seed!r}: expected a whole number >= 0")


def drive(controller: str | Path | Callable, *, track: str | Path | None = None, laps: int = 1,
          time_limit_s: float = 60.0, video: str | Path | None = None,
          csv: str | Path | None = None, plot: str | Path | None = None,
          summary: str | Path | None = None, seed: int = 0,
          car: str | Path | CarDescription | None = None, dt_s: float = 0.002,
          wall_limit_s: float = 10.0) -> RunResult:
    """Run ``controller`` (a ``.py`` file with ``main(spinner)``, or such a callable).

    ``track``: layout ``.txt`` | trackgen folder | world file | model folder (default: the
    bundled figure-8). ``laps``: laps to finish. ``time_limit_s``: simulated seconds.
    ``video`` (.mp4) / ``csv`` / ``plot`` (.png) / ``summary`` (.json): output paths or None.
    ``seed``: camera-noise generator seed. ``car``: car TOML path or description.
    ``dt_s``: physics step. ``wall_limit_s``: watchdog limit of wall time without progress.

    Bad input (files, options) raises :class:`SimError` / ``CarDescriptionError`` before
    anything is written. A failing controller does not raise: the result has
    ``outcome == "controller_error"`` and ``error`` (a :class:`ControllerError` with the
    user's traceback), and every requested output is still written.
    """
    from simrunner.sensors.camera import Camera
    from simrunner.run.judge import Judge
    from simrunner.car.effects import make_sim

    _check_options(laps, time_limit_s, seed, dt_s, wall_limit_s)
    code, ctrl_path, main = None, None, None
    if callable(controller):
        main = controller
        try:
            user_file = inspect.getsourcefile(controller)
        except TypeError:
            user_file = None
    else:
        ctrl_path = Path(controller)
        code = compile_controller(ctrl_path)
        user_file = code.co_filename
    car_desc = car if isinstance(car, CarDescription) else load_car(car)
    track_spec = Path(track) if track is not None else default_track()
    sim_track = _load_track(track_spec, car_desc)

    # make_sim: a plain CarSim when every effect of the car description is neutral,
    # otherwise an EffectSim applying them (docs/effects.md)
    sim = make_sim(car_desc, dt_s=dt_s, start=sim_track.start, surface_z_m=sim_track.surface_z_m)
    camera = Camera(car_desc.camera, sim_track)
    judge = Judge(sim_track, laps=int(laps))
    log = TelemetryLog()
    recorder = None
    if video is not None:
        from simrunner.run.video import VideoRecorder

        recorder = VideoRecorder(video, camera_fps=car_desc.camera.fps_hz, render=camera.render,
                                 raster=sim_track.raster, laps=int(laps),
                                 line_row=car_desc.camera.default_row,
                                 car_length_m=car_desc.chassis.wheelbase_m + 0.05,
                                 car_width_m=car_desc.chassis.track_m)
    work = _FrameWork(sim, judge, log, float(time_limit_s), recorder)
    clock = LockstepClock(sim, dt_s=dt_s, frame_period_s=1.0 / car_desc.camera.fps_hz,
                          on_frame=work)
    work.clock = clock
    clock.on_row_command = work.command_applied
    session = Session(clock=clock, camera=camera, car=car_desc,
                      rng=np.random.default_rng(int(seed)), video=recorder)

    outcome, message, error = None, "", None
    module_name = "simrunner_controller"
    modules_before = set(sys.modules)
    added_path = None
    # The loop's garbage is short-lived: freezing the objects that exist now keeps the
    # collector's older-generation passes from walking every loaded module (~3 % of a lap).
    # Only when nothing is frozen already, so unfreezing afterwards restores the state.
    frozen = hasattr(gc, "freeze") and gc.get_freeze_count() == 0
    if frozen:
        gc.freeze()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    watchdog = _Watchdog(clock, wall_limit_s, user_file)
    session.activate()
    try:
        with watchdog:
            try:
                clock.start()
                if code is not None:
                    module = types.ModuleType(module_name)
                    module.__file__ = code.co_filename
                    sys.modules[module_name] = module
                    added_path = str(Path(code.co_filename).parent)
                    sys.path.insert(0, added_path)
                    exec(code, module.__dict__)
                    main = _controller_main(module, ctrl_path)
                main(Spinner(session=session))
            except RunFinished as exc:
                watchdog.disarm()
                outcome, message = exc.outcome, exc.message
            except ControllerFileError:
                watchdog.disarm()
                raise
            except KeyboardInterrupt:
                watchdog.disarm()
                outcome, message = "interrupted", "Ctrl-C"
            except Exception as exc:
                watchdog.disarm()
                outcome = "controller_error"
                tb = user_traceback(exc)
                message = tb.strip().splitlines()[-1] if tb.strip() else repr(exc)
                error = ControllerError(message, tb)
            else:
                watchdog.disarm()
    except ControllerFileError:
        if recorder is not None:
            recorder.close()
            Path(video).unlink(missing_ok=True)
        raise
    finally:
        if frozen:
            gc.unfreeze()
        session.deactivate()
        sys.modules.pop(module_name, None)
        if added_path is not None:
            _forget_modules_from(added_path, set(sys.modules) - modules_before)
            if added_path in sys.path:
                sys.path.remove(added_path)
    wall_s, cpu_s = time.perf_counter() - wall0, time.process_time() - cpu0
    if outcome not in ("controller_error", "interrupted"):
        if clock.finished is not None:
            outcome, message = clock.finished.outcome, clock.finished.message
        elif outcome is None:
            outcome, message = "controller_returned", "main() returned"

    sim_s = clock.time_s
    result = RunResult(outcome=outcome, laps=int(laps), laps_completed=judge.laps_completed,
                       lap_times_s=judge.lap_times_s, sim_time_s=sim_s, wall_time_s=wall_s,
                       real_time_factor=sim_s / wall_s if wall_s > 0 else math.inf,
                       track=str(track_spec), seed=int(seed), message=message, cpu_time_s=cpu_s,
                       error=error,
                       telemetry=log)
    _write_outputs(result, recorder, sim_track, csv=csv, plot=plot, summary=summary)
    return result


def _forget_modules_from(folder: str, names: set[str]) -> None:
    """Unload helper modules a controller imported from its own folder (a later run of
    another folder's ``helper.py`` must not get this one)."""
    for name in names:
        f = getattr(sys.modules.get(name), "__file__", None) or ""
        if f and os.path.dirname(os.path.abspath(f)) == folder:
            sys.modules.pop(name, None)


def _write_outputs(result: RunResult, recorder, sim_track, *, csv, plot, summary) -> None:
    """Close the video and write CSV, plot and summary (all attempted; first error raised)."""
    errors: list[SimError] = []
    if recorder is not None:
        try:
            p = recorder.close()
            if p is not None:
                result.outputs["video"] = str(p)
        except SimError as exc:
            errors.append(exc)
    if csv is not None:
        try:
            result.outputs["csv"] = str(result.telemetry.write_csv(csv))
        except SimError as exc:
            errors.append(exc)
    if plot is not None:
        try:
            from simrunner.run.plot import plot_run

            result.outputs["plot"] = str(plot_run(result.telemetry, sim_track, plot,
                                                  title=_plot_title(result)))
        except SimError as exc:
            errors.append(exc)
    if summary is not None:
        path = Path(summary)
        result.outputs["summary"] = str(path)
        tmp = path.with_name(path.name + ".tmp")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(json.dumps(result.summary(), indent=2) + "\n")
            os.replace(tmp, path)
        except OSError as exc:
            errors.append(SimError(f"{path}: cannot write summary ({exc.strerror})"))
    if errors:
        raise errors[0]


def _plot_title(r: RunResult) -> str:
    laps = ", ".join(f"{t:.2f} s" for t in r.lap_times_s) or "none"
    return f"{Path(r.track).name}: {r.outcome}, laps {r.laps_completed}/{r.laps} ({laps})"
