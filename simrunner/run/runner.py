"""Run a controller's ``main(spinner)`` against the simulated car: :func:`drive`.

``drive`` has three parts: load (the controller - :mod:`simrunner.run.controller` -, the car
description and the track), wire one run (:class:`Run`: car model, camera, judge, run
recorder, video, clock, Spinner session; every part is owned by the run, nothing points back
at it) and write the outputs (:mod:`simrunner.reports.outputs`).

One thread: the controller runs in the calling thread; the simulation advances inside its
Spinner calls (:mod:`simrunner.run.clock`). At every camera frame :class:`FrameWork` judges
(laps, off track), records the run-log row and hands the frame to the video writer thread.

The run ends when the judge counts the laps (``finished``; in the race once the car's stop
after the finish line is judged, :mod:`simrunner.run.rules`), too many wheels leave the road
(``off_track``: 3 by default, the rules'), the car leaves the course (``off_course``: it
turned at a crossing or cut across), the simulated time limit passes (``timeout``) — then the next Spinner call
raises :class:`~simrunner.errors.RunFinished` — when ``main`` returns
(``controller_returned``), when it raises (``controller_error``; also bad commands such as
NaN), or when it spends ``wall_limit_s`` of wall time without letting simulated time pass
(``stalled``: a SIGALRM watchdog, main thread only), or on Ctrl-C (``interrupted``).
The run log, video, plot and summary are written in every case but one: a controller stuck
inside one C-level call that holds the interpreter, which the hard watchdog ends with the
process (:mod:`simrunner.run.watchdog`); under a supervisor (:mod:`simrunner.run.supervise`,
``simrunner drive``) the run log streams to disk and the supervisor writes the rest from it.
"""
from __future__ import annotations

import gc
import os
import threading
import time
from pathlib import Path
import numpy as np

from simrunner.car import CarModel
from simrunner.errors import ControllerError, ControllerFileError, RunFinished, SimError
from simrunner.run.clock import Command, LockstepClock
from simrunner.run.controller import Controller, MainFn, load_controller, user_location, user_traceback
from simrunner.run.faults import (ControllerGuards, SignalGuard, Terminated, end_forked_child, exit_outcome,
                                  stray_threads)
from simrunner.run.judge import Judge
from simrunner.telemetry.log import RunRecorder
from simrunner.reports.outputs import Outputs, check_outputs, write_outputs
from simrunner.run.result import Outcome, RunResult
from simrunner.run.events import event_start, event_track, make_monitor
from simrunner.run.rules import EVENTS
from simrunner.run.settings import RunSettings
from simrunner.run.spinner import Session, Spinner
from simrunner.run.supervise import current_supervision
from simrunner.run.watchdog import Watchdog
from simrunner.track import SimTrack
from trackgen.outdir import process_umask
from vehicle.description import CarDescription, load_car

_DATA_DIR = Path(__file__).resolve().parent.parent / "data"
UNLIMITED_LAPS = 10**6  # the judge's laps in a discipline that counts laps until its time is up
DEFAULT_TRACK_NAME = "thesis_figure8.txt"


def default_track() -> Path:
    """The bundled default track layout (the thesis's figure-8, Fig. 4.2)."""
    return _DATA_DIR / DEFAULT_TRACK_NAME


def _c_environment() -> dict[bytes, bytes] | None:
    """The process's environment as the C library holds it (``environ``, environ(7)), which a
    C controller's setenv / unsetenv / putenv (or Python's os.putenv) change behind
    os.environ; None where it cannot be read."""
    try:
        import ctypes

        env = ctypes.POINTER(ctypes.c_char_p).in_dll(ctypes.CDLL(None), "environ")
    except (OSError, ValueError, AttributeError):  # not a POSIX C library
        return None
    out: dict[bytes, bytes] = {}
    i = 0
    while env and env[i] is not None:  # (NULL after clearenv)
        key, sep, value = env[i].partition(b"=")
        if sep:
            out.setdefault(key, value)
        i += 1
    return out


def _process_state() -> tuple[str, dict[str, str], dict[bytes, bytes] | None, int]:
    """What a controller may change of the process, for :func:`_restore_process_state`: the
    working directory, os.environ, the C library's environment and the file-creation mask."""
    return os.getcwd(), dict(os.environ), _c_environment(), process_umask()


def _restore_process_state(cwd: str, environ: dict[str, str], c_environ: dict[bytes, bytes] | None,
                           umask: int) -> None:
    """The working directory, the file-creation mask (the outputs' permissions) and the
    environment (os.environ and the C library's, :func:`_c_environment`) as they were before
    the controller ran."""
    if process_umask() != umask:
        os.umask(umask)
    try:
        if os.getcwd() != cwd:
            os.chdir(cwd)
    except OSError:  # (the controller removed it: stay where it left us)
        pass
    if os.environ != environ:
        for key in [k for k in os.environ if k not in environ]:
            del os.environ[key]
        os.environ.update(environ)
    now = _c_environment() if c_environ is not None else None
    if now is None:
        return
    for key in now.keys() - c_environ.keys():
        try:
            os.unsetenv(key)
        except (OSError, ValueError):  # a name unsetenv refuses (empty, with '='): leave it
            pass
    # every entry set again, even one whose value is unchanged: putenv(3) puts the caller's own
    # string in environ, and a C controller's (its static data, a C++ constructor's at load time)
    # is unmapped when its library is unloaded after the run - the next getenv would read freed
    # memory. os.putenv is setenv(3) (CPython 3.9+), which stores a copy of its own.
    for key, value in c_environ.items():
        try:
            os.putenv(key, value)
        except (OSError, ValueError):
            pass


# -- the run log's extra columns -------------------------------------------------------------
def extra_columns(track: SimTrack, car: CarDescription, sim: CarModel, seed: int, imu_noise=None):
    """The run log's columns beyond the base ones (``simrunner.telemetry.log.EXTRA_COLUMNS``) and
    a function ``(pose, t_s) -> their values``: the car's height and pitch on a track with hills
    (``pose`` is then a ``Pose3``), its encoders' counts and its IMU's sample at each frame, a
    duty-commanded car's motor duties.
    The log's encoders and IMU are copies of the car's own (the same device, seed and noise,
    ``imu_noise``: the run's :class:`~simrunner.sensors.imu.ImuNoise`, None: its own), so that
    logging them does not change what the controller reads. ``((), None)`` without any."""
    from simrunner.telemetry.log import DUTY_COLUMNS, IMU_COLUMNS, LIFT_COLUMNS

    names: list[str] = []
    parts: list = []
    if track.terrain:
        names += LIFT_COLUMNS
        parts.append(lambda pose, t: (pose.z_m, pose.pitch_rad))
    if car.encoders is not None or car.imu is not None:
        from simrunner.sensors.imu import ON, Encoders, Imu

        if car.encoders is not None:
            wheels = ON[car.encoders.wheels]
            names += [f"enc_{w.lower()}" for w in wheels]
            counts = Encoders(car.encoders).counter(wheels, sim)
            parts.append(lambda pose, t: counts())
        if car.imu is not None:
            imu = Imu(car.imu, seed, imu_noise)
            names += IMU_COLUMNS
            truth = sim.imu_reader((car.imu.x_m, car.imu.y_m, car.imu.z_m))
            parts.append(lambda pose, t: imu.sample("log", t, truth))
    if car.drive.command == "duty":
        names += DUTY_COLUMNS
        parts.append(lambda pose, t: (*sim.duties, sim.duty_cmd))
    if not parts:
        return (), None
    if len(parts) == 1:
        return tuple(names), parts[0]

    def values(pose, t) -> tuple:  # each part gives a tuple
        out = ()
        for part in parts:
            out += part(pose, t)
        return out

    return tuple(names), values


# -- per-frame work -----------------------------------------------------------------------
class FrameWork:
    """The clock's ``on_frame``: judge, run-log row, video frame; returns how the run ends
    (or None). Holds the parts it uses, never the clock.

    Ends the run when the judge counts the laps, when ``off_track_wheels`` wheels are off the
    road, when the car leaves the course, or at the time limit; with ``keep_driving`` leaving
    the track or the course is only counted (the run's warnings). A discipline's
    ``monitor`` (:mod:`simrunner.run.events`) sees every frame and decides what the laps and
    the time limit mean (the race's stop after the line, the figure 8's laps in the time)."""

    def __init__(self, sim: CarModel, judge: Judge, recorder: RunRecorder, time_limit_s: float,
                 video=None, *, judged: bool = True, keep_driving: bool = False,
                 off_track_wheels: int = 1, monitor=None):
        self.sim, self.judge, self.recorder, self.video = sim, judge, recorder, video
        self.time_limit_s = time_limit_s
        self.events: list = []
        self._contacts = sim.wheel_contacts
        self._record = recorder.frame
        self.extra = None  # (pose, t) -> the values of the recorder's extra columns (Run sets it)
        self.judged = judged  # False on a free floor: no laps, no off track
        self.keep_driving = keep_driving  # leaving the track is recorded, does not end the run
        self.off_track_wheels = off_track_wheels
        self.off_track_count = 0
        self.first_off_track = ""
        self.off_course_count = 0
        self.first_off_course = ""
        self.monitor = monitor
        self.has_solids = False  # objects on the track (Run.place_solid): a touch ends the run
        self.solids: tuple = ()  # ... and the video's top view draws them
        self.touch_count = 0
        self.first_touch = ""
        self._touching = False

    def __call__(self, k: int, t: float, pose, cmd: Command,
                 row_cmd: Command | None) -> tuple[Outcome, str] | None:
        sim, judge = self.sim, self.judge
        events = None
        if self.judged:
            events = judge.update(t, pose, self._contacts())
            if events:
                self.events.extend(events)
            off = judge.off_track
            lap = judge.laps_completed
        else:
            off, lap = False, 0
        speed, steer = sim.speed_mps, sim.steer_rad
        if self.extra is not None:  # hills, encoders, an IMU (extra_columns)
            self._record(k, t, pose.x_m, pose.y_m, pose.yaw_rad, speed, steer, sim.yaw_rate_radps,
                         cmd, row_cmd, lap, off, *self.extra(pose, t))
        else:
            self._record(k, t, pose.x_m, pose.y_m, pose.yaw_rad, speed, steer, sim.yaw_rate_radps,
                         cmd, row_cmd, lap, off)
        if self.video is not None:
            self.video.frame_boundary(k, t, pose, {
                "speed": speed, "steer": steer, "speed_cmd": cmd[0], "steer_cmd": cmd[1],
                "lap": lap, "off_track": off, "solids": self.solids})
        monitor = self.monitor
        if self.has_solids:
            touched = sim.touched_solids()
            if touched:
                text = f"touched the {touched[0]} at t = {t:.3f} s"
                if not self.keep_driving:
                    if monitor is not None:
                        monitor.verdict.details["touched"] = touched[0]
                    return Outcome.TOUCHED, text
                if not self._touching:
                    self.touch_count += 1
                    self.first_touch = self.first_touch or text
            self._touching = bool(touched)
        if monitor is not None:
            end = monitor.frame(t, pose, speed)
            if end is not None:
                return end
        if lap >= judge.laps:
            if monitor is None:
                return Outcome.FINISHED, f"{lap} lap(s) completed"
            return monitor.at_laps(t, speed, len(judge.off_wheels) >= self.off_track_wheels)
        if off:
            text = (f"off track at t = {t:.3f} s (wheel(s) {', '.join(judge.off_wheels)} "
                    f"{'partly ' if judge.any_part else ''}off the road)")
            if len(judge.off_wheels) >= self.off_track_wheels and not self.keep_driving:
                return Outcome.OFF_TRACK, text
            if events and any(e.kind == "off_track" for e in events):
                self.off_track_count += 1
                self.first_off_track = self.first_off_track or text
        if events and any(e.kind == "off_course" for e in events):
            text = f"{judge.off_course} at t = {t:.3f} s"
            if not self.keep_driving:
                return Outcome.OFF_COURSE, text
            self.off_course_count += 1
            self.first_off_course = self.first_off_course or text
        if t >= self.time_limit_s - 1e-9:
            if monitor is not None:
                return monitor.at_time_limit(t)
            return Outcome.TIMEOUT, f"time limit of {self.time_limit_s:g} s simulated time reached"
        return None


# -- one run, wired -----------------------------------------------------------------------
class Run:
    """Everything one run owns, built from its inputs; :meth:`execute` runs a controller.

    Two ``Run`` objects share nothing (the Spinner finds its session through a context
    variable), so runs in one process do not interfere.
    """

    def __init__(self, track: SimTrack, car: CarDescription, settings: RunSettings, *,
                 video_path: str | Path | None = None, record_text: bool = False,
                 csv_path: str | Path | None = None, video_fps: float | None = None,
                 umask: int | None = None):
        from simrunner.car.effects import make_sim
        from simrunner.sensors.camera import Camera

        from simrunner.run.start import start_pose

        settings = settings.for_track(track)  # the time limit's default grows with the laps
        settings = event_start(settings, track)  # a discipline's own start (speed_limit: R20)
        self.track, self.car, self.settings = track, car, settings
        self.time_limit_s = settings.time_limit_s
        self.start = start_pose(track, car, settings)
        # make_sim: a plain CarSim when every effect of the car description is neutral,
        # otherwise an EffectSim applying them (docs/effects.md)
        self.sim: CarModel = make_sim(car, dt_s=settings.dt_s, start=self.start,
                                      surface_z_m=track.surface_z_m, terrain=track.terrain)
        self.camera = Camera(car.camera, track)
        self.imager = None
        if car.camera.model != "ideal":  # the physical camera (docs/camera.md)
            from simrunner.sensors.imaging import Imager

            self.imager = Imager(self.camera, track.lighting, surface_z_m=track.surface_z_m)
        event_laps = None if settings.event is None else EVENTS[settings.event].laps
        self.judge = Judge(track, laps=settings.laps if settings.event is None
                           else (event_laps or UNLIMITED_LAPS),
                           wheel_off="whole" if settings.event is None else EVENTS[settings.event].wheel_off)
        self.monitor = None if settings.event is None else make_monitor(settings.event, self)
        self.csv = None
        supervision = current_supervision()
        if csv_path is None and supervision is not None and supervision.csv_path is not None:
            csv_path = supervision.csv_path  # the supervisor's copy of the log
        self.imu_noise = None  # what the car's IMU adds to its samples, shared by its two copies
        if car.imu is not None:
            from simrunner.sensors.imu import ImuNoise

            self.imu_noise = ImuNoise(car.imu, settings.seed)
        extra, extra_values = extra_columns(track, car, self.sim, settings.seed, self.imu_noise)
        if csv_path is not None:  # written as the run goes (simrunner.telemetry.stream)
            from simrunner.telemetry.stream import CsvStream

            self.csv = CsvStream(csv_path, extra=extra, umask=umask)
        self.recorder = RunRecorder(record_text=record_text or video_path is not None
                                    or csv_path is not None, sink=self.csv, extra=extra)
        self.video = None
        if video_path is not None:
            from simrunner.reports.video import VideoRecorder

            self.video = VideoRecorder(video_path, camera_fps=1.0 / car.camera.frame_period_s(),
                                       **({} if video_fps is None else {"max_fps": video_fps}),
                                       render=self._render_view, view_state=lambda: self.session.exposure_s,
                                       raster=track.raster,
                                       lighting=track.lighting, surface_z_m=track.surface_z_m,
                                       laps=settings.laps if settings.event is None else (event_laps or 0),
                                       line_row=car.camera.default_row,
                                       car_length_m=car.chassis.wheelbase_m + 0.05,
                                       car_width_m=car.chassis.track_m, umask=umask)
        self.frames = FrameWork(self.sim, self.judge, self.recorder, settings.time_limit_s, self.video,
                                judged=track.judged, keep_driving=settings.keep_driving,
                                off_track_wheels=settings.off_track_wheels, monitor=self.monitor)
        self.frames.extra = extra_values
        self.clock = LockstepClock(self.sim, dt_s=settings.dt_s,
                                   frame_period_s=car.camera.frame_period_s(), on_frame=self.frames)
        if self.imager is not None and self.imager.spec.motion_blur_samples > 1:
            sim = self.sim  # a latest frame (Spinner.latest_image) blurs by the boundary's motion
            self.clock.twist_fn = lambda: (sim.speed_mps, sim.lateral_speed_mps, sim.yaw_rate_radps)
        self.session = Session(clock=self.clock, camera=self.camera, car=car,
                               rng=np.random.default_rng(settings.seed), recorder=self.recorder,
                               video=self.video, params=settings.params, imager=self.imager)
        self.session.seed, self.session.surface_z_m = settings.seed, track.surface_z_m
        self.session.imu_noise = self.imu_noise
        if settings.mcu_time is not None:  # the controller's own time (simrunner.run.mcu)
            from simrunner.run.mcu import McuTime

            self.session.mcu = McuTime(self.clock, scale=settings.mcu_scale,
                                       fixed_s=None if settings.mcu_time == "measured" else settings.mcu_time)
            self.clock.run_handler = self.session.mcu.run_handler  # (a Python handler's time, measured)
        for box in track.boxes:  # the layout's @box objects stand there from the start
            self.place_solid(box)
        self.wall_time_s = 0.0
        self.cpu_time_s = 0.0
        self.signal_guard = None  # a faults.SignalGuard, when drive() installed one

    def place_solid(self, solid) -> None:
        """Put ``solid`` (:class:`worlds.solids.Solid`) on the track now: a rigid body the car
        can touch, seen by the cameras and the range sensors."""
        self.sim.add_solid(solid)
        if self.video is not None:  # the frames before this one are drawn without it
            self.video.drain()
        self.camera.solids = self.camera.solids + (solid,)
        self.frames.has_solids = True
        self.frames.solids = self.camera.solids

    def _render_view(self, pose, exposure_s: float) -> np.ndarray:
        """The debug video's camera view in a frame the controller took no image: the camera's
        own image without temporal noise (the physical camera at ``exposure_s``, the exposure
        in force when the frame began, :meth:`Imager.preview`: within 1 DN of ``get_image()``'s
        without noise; drawn in the video's thread)."""
        if self.imager is None:
            return self.camera.render(pose)
        return self.imager.preview(pose, exposure_s=exposure_s)

    def execute(self, controller: Controller) -> tuple[Outcome, str, ControllerError | None]:
        """Run ``controller`` to the end of the run: ``(outcome, message, error)``.

        A controller file without a usable ``main`` raises :class:`ControllerFileError`
        (the video, if any, is removed); every other fault is an outcome.
        """
        outcome, message, error = None, "", None
        clock = self.clock
        watchdog = Watchdog(clock, self.settings.wall_limit_s, controller.user_file)
        wall0, cpu0 = time.perf_counter(), time.process_time()
        for n, text in enumerate(controller.load_warnings()):  # found at its load: said first
            self.session.warn_once(f"host_clock:{n}", text)
        self.session.activate()
        if self.signal_guard is not None:
            self.signal_guard.clock = clock
        # what the controller's process state was: a controller that changes directory, the
        # environment or the umask must not move this run's outputs, change their permissions
        # or change the next run of a batch worker
        state = _process_state()
        try:
            with _gc_frozen(), watchdog, ControllerGuards(self.session):
                try:
                    clock.start()
                    with controller.loaded() as main:
                        try:
                            main(Spinner(session=self.session))
                        finally:
                            end_forked_child()  # a process the controller forked ends where its main does
                except RunFinished as exc:
                    outcome, message = Outcome(exc.outcome), exc.message
                except ControllerFileError:
                    raise
                except KeyboardInterrupt as exc:
                    outcome, message = Outcome.INTERRUPTED, (
                        f"{exc.args[0]} received" if isinstance(exc, Terminated) else "Ctrl-C")
                except SystemExit as exc:  # sys.exit / os._exit in the controller
                    outcome, message, error = exit_outcome(exc)
                except ControllerError as exc:  # already described (a C controller's fault)
                    outcome, message, error = Outcome.CONTROLLER_ERROR, str(exc), exc
                except Exception as exc:
                    tb = user_traceback(exc)
                    message = tb.strip().splitlines()[-1] if tb.strip() else repr(exc)
                    where = user_location(tb)
                    outcome, error = Outcome.CONTROLLER_ERROR, ControllerError(message, tb)
                    message = f"{message} at {where}" if where else message  # as a C fault's
                finally:
                    watchdog.disarm()
        except ControllerFileError:
            if self.video is not None:
                self.video.discard()
            if self.csv is not None:
                self.csv.discard()
            raise
        finally:
            self.session.deactivate()
            if self.signal_guard is not None:
                self.signal_guard.clock = None
            _restore_process_state(*state)
        self.wall_time_s = time.perf_counter() - wall0
        self.cpu_time_s = time.process_time() - cpu0
        if outcome not in (Outcome.CONTROLLER_ERROR, Outcome.INTERRUPTED):
            if clock.finished is not None:
                outcome, message = Outcome(clock.finished.outcome), clock.finished.message
            elif outcome is None:
                outcome, message = Outcome.CONTROLLER_RETURNED, "main() returned"
        if self.monitor is not None and outcome != Outcome.FINISHED:
            self.monitor.failed(outcome)
        frames = self.frames
        if frames.off_track_count:
            n = frames.off_track_count
            why = ("keep_driving" if self.settings.keep_driving else
                   f"fewer than {frames.off_track_wheels} wheels off the road do not end the run")
            self.session.warn_once("off_track", (
                f"left the track {n} time{'s' if n > 1 else ''} (first: {frames.first_off_track}); "
                f"kept driving ({why})"))
        if frames.touch_count:
            self.session.warn_once("touched", f"kept touching objects on the track (first: {frames.first_touch}); "
                                   "kept driving (keep_driving)")
        if frames.off_course_count:
            n = frames.off_course_count
            self.session.warn_once("off_course", (
                f"left the course {n} time{'s' if n > 1 else ''} (first: {frames.first_off_course}); "
                f"kept driving (keep_driving)"))
        return outcome, message, error

    @property
    def warnings(self) -> list[str]:
        """What the run noticed and did not stop for (speed capped, track left, ...)."""
        return list(self.session.warnings)


class _gc_frozen:
    """The loop's garbage is short-lived: freezing the objects that exist now keeps the
    collector's older-generation passes from walking every loaded module (~3 % of a lap).
    Only when nothing is frozen already, so unfreezing afterwards restores the state."""

    def __enter__(self) -> None:
        self.frozen = gc.get_freeze_count() == 0
        if self.frozen:
            gc.freeze()

    def __exit__(self, *exc) -> None:
        if self.frozen:
            gc.unfreeze()


# -- drive ----------------------------------------------------------------------------------
def resolve_track(track: str | Path | SimTrack | None, car: CarDescription) -> tuple[SimTrack, str]:
    """``(SimTrack, label)`` for a track argument of :func:`drive` (None or ``"default"`` = the
    default; ``"floor"`` = the free floor, :mod:`simrunner.track.floor`)."""
    if isinstance(track, SimTrack):
        return track, str(track.source)
    if isinstance(track, str) and track == "default" and not Path(track).exists():
        track = None  # the bundled track by its name (simrunner batch --tracks default too)
    if isinstance(track, str) and track == "floor":
        from simrunner.track.floor import floor_track

        return floor_track(), "floor"
    from simrunner.track import load_track

    path = Path(track) if track is not None else default_track()
    if not path.exists():
        raise SimError(f"{path}: no such track (expected a layout .txt, a trackgen folder, a "
                       f"world file or a Gazebo model folder)")
    return load_track(path, car=car), str(path)


def drive(controller: str | Path | MainFn, *, track: str | Path | SimTrack | None = None,
          car: str | Path | CarDescription | None = None, settings: RunSettings | None = None,
          video: str | Path | None = None, csv: str | Path | None = None,
          plot: str | Path | None = None, summary: str | Path | None = None,
          video_fps: float | None = None, **setting_values) -> RunResult:
    """Run ``controller`` (a ``.py`` file with ``main(spinner)``, or a callable) on ``track``.

    ``track``: a layout ``.txt``, trackgen folder, world file, Gazebo model folder, an
    already loaded :class:`~simrunner.track.SimTrack` (reuse it across runs), ``"floor"``
    (an empty floor, not judged) or None for the bundled thesis figure-8. ``car``: a car TOML path, a ``CarDescription`` or None
    (the default car). ``settings``: a :class:`RunSettings`; or give its fields as keywords
    (``laps=2, time_limit_s=30, seed=1, dt_s=0.002, wall_limit_s=10, start=(x_m, y_m,
    yaw_rad), start_before_finish_m=0.4, keep_driving=True``). ``video``, ``csv``, ``plot``,
    ``summary``: output paths (None: not written), all checked before the run; the CSV is
    written as the run goes, so a run cut short keeps its rows. ``video_fps``: the video's
    highest frame rate (default 30: every second frame of a 50 fps camera).

    Bad input (files, settings) raises a :class:`~simrunner.errors.SimError` (or the car
    description's error) before anything is written. A failing controller does not raise:
    the result has ``outcome == "controller_error"`` and ``error`` (a
    :class:`ControllerError` with the user's traceback), and every requested output is
    still written.
    """
    if settings is None:
        settings = RunSettings(**setting_values)
    elif setting_values:
        raise SimError(f"drive(): give either settings= or setting keywords, not both "
                       f"({', '.join(setting_values)})")
    outputs = Outputs(video=video, csv=csv, plot=plot, summary=summary, video_fps=video_fps)
    check_outputs(outputs)  # before anything is loaded or driven
    with SignalGuard() as signals:
        # the process as it was before the controller was loaded: a C/C++ controller's
        # constructors run at its load (a setenv, chdir or umask there must not reach the
        # outputs' places and permissions, nor the next run of a batch worker)
        state, ctrl = _process_state(), None
        try:
            ctrl = load_controller(controller)
            car_desc = car if isinstance(car, CarDescription) else load_car(car)
            if track is None and settings.event is not None:
                track = event_track(settings.event)  # the discipline's own layout (None: the default)
            sim_track, track_label = resolve_track(track, car_desc)
            here = Path(state[0])  # (the outputs' places: a constructor's chdir must not move them)
            run = Run(sim_track, car_desc, settings, video_path=None if video is None else here / video,
                      csv_path=None if csv is None else here / csv, video_fps=video_fps, umask=state[3])
            run.signal_guard = signals
            threads_before = set(threading.enumerate())
            outcome, message, error = run.execute(ctrl)
        finally:
            _restore_process_state(*state)  # (first: no environ entry is then the library's)
            if ctrl is not None:
                ctrl.close()  # a C controller's library unloaded now, not whenever it is collected
        signals.writing = True
        judge = run.judge
        warnings = run.warnings
        stray = stray_threads(threads_before)
        if stray:
            warnings.append(f"the controller left {', '.join(stray)} running (not waited for)")
        laps = settings.laps if settings.event is None else (EVENTS[settings.event].laps or judge.laps_completed)
        result = RunResult(outcome=outcome, laps=laps, laps_completed=judge.laps_completed,
                           lap_times_s=judge.lap_times_s, sim_time_s=run.clock.time_s,
                           wall_time_s=run.wall_time_s, track=track_label, seed=settings.seed,
                           message=message, cpu_time_s=run.cpu_time_s, error=error,
                           log=run.recorder.freeze(track_label), frames=len(run.recorder),
                           warnings=warnings, stray_threads=len(stray),
                           signal=signals.received if outcome == Outcome.INTERRUPTED else None,
                           event=settings.event, verdict=run.monitor.verdict if run.monitor else None,
                           lap_distances_m=judge.lap_distances_m, lap_courses_m=judge.lap_courses_m,
                           course_from_start_m=judge.course_from_start_m,
                           course_length_m=None if sim_track.course is None else sim_track.course.length_m,
                           unused_params=tuple(sorted(set(settings.params) - run.session.params_read)),
                           params_read=tuple(sorted(run.session.params_read)))
        run.recorder.finish()
        write_outputs(result, outputs, run.video, sim_track, csv_stream=run.csv)
    return result


__all__ = ["drive", "Run", "FrameWork", "RunResult", "RunSettings", "Outcome", "default_track",
           "resolve_track"]
