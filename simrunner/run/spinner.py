"""The thesis's Spinner API (Appendix A.2) in Python, on a deterministic lockstep clock.

A controller is a Python file with ``main(spinner)``; ``simrunner drive FILE`` calls it with
a ready :class:`Spinner`. Units without norm functions (the defaults): speed in m/s,
steering in radians (bicycle-equivalent, positive = left), time in s, position in m.

Norm functions (all take ``(speed, angle)`` in the controller's units, speed first, like the
thesis; each is optional):

- ``speed_norm(speed, angle) -> speed_mps``      controller speed -> m/s (default: identity)
- ``speed_denorm(speed_mps, angle) -> speed``    m/s -> controller speed, for ``get_speed``
- ``turn_norm(speed, angle) -> steer_rad``        controller angle -> radians, + = left
- ``diff_norm(speed_mps, steer_rad) -> yaw_rate_radps``  rear differential (thesis eq. 5.2,
  5.3); takes the already normalised command; default ``v * sin(delta) / L``.

Give a controller its own norms with :meth:`Spinner.configure` (returns the spinner)::

    def main(spinner):
        # the real car's -512..512 servo values, direction swapped (thesis 3.3)
        s = spinner.configure(turn_norm=lambda speed, angle: -angle / 512 * 0.40)

Time (see :mod:`simrunner.run.clock`): simulated time advances only inside ``get_image``
(to the next camera frame), ``get_time``/``get_speed``/``get_position`` (one physics step
each, so polling loops make progress) and ``sleep`` (``ceil(seconds / dt)`` steps, at least
one). ``set_*`` and ``add_*`` only store values; commands act from the next physics step.
When the run is over (laps done, time limit, off track) the next waiting call raises
:class:`~simrunner.errors.RunFinished`, a ``BaseException`` that ends ``main``.

Images: ``get_image()`` returns the whole ``(H, W)`` uint8 gray image (row 0 = farthest,
column 0 = the car's left); ``get_image(k)`` returns row ``k`` as a ``(1, W)`` uint8 array
(like a ``cv::Mat`` row). ``Spinner.LINE_ROW`` (default car) / ``spinner.line_row`` (this
car) is ``camera.default_row``: the row that plays the real line camera.
"""
from __future__ import annotations

import contextvars
import math
import os
import sys
import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

import numpy as np

from vehicle.description import CarDescription

from simrunner.errors import CommandError, SimError
from simrunner.run.clock import LockstepClock
from simrunner.run.context import SESSION, current_session  # noqa: F401  (current_session: re-exported)
from simrunner.telemetry.log import RunRecorder
from simrunner.run.params import ParamValue, convert

if TYPE_CHECKING:
    from simrunner.run.pixy2 import Pixy2
    from simrunner.reports.video import VideoRecorder
    from simrunner.sensors.camera import Camera
    from simrunner.sensors.imaging import Imager

NormFn = Callable[[float, float], float]
MIN_INTERRUPT_PERIOD_S = 1e-5  # every(): a 100 kHz timer at most (faster ones are not a control loop)
_NO_WAIT = ("no simulated time passes in a handler; wait in the main loop and leave the "
            "handler to read sensors and set commands")

_RUN_DIR = os.path.dirname(os.path.abspath(__file__)) + os.sep  # simrunner/run/ (not the caller's code)
_current_session = SESSION  # the run executing in this context (simrunner.run.context)
_get_ident = threading.get_ident


def _call_in_forked_child() -> int:
    """``_get_ident`` in a process the running controller forked (every Spinner call asks it
    first): the run is the parent's, so the call ends this process with a message."""
    sys.stdout.flush()
    sys.stderr.write(f"simrunner: a Spinner call in process {os.getpid()}, which the controller fork()ed from "
                     f"process {os.getppid()}: only the controller's own process drives the car; this one ends "
                     "(exit status 70)\n")
    sys.stderr.flush()
    os._exit(70)


def _after_fork_in_child() -> None:
    """A fork from the thread of an executing run (the controller's, os.register_at_fork): in
    the child, Spinner calls end the process (simrunner.run.faults ends it where main ends)."""
    global _get_ident
    session = _current_session.get()
    if session is not None and session.thread_id == threading.get_ident():
        _get_ident = _call_in_forked_child


os.register_at_fork(after_in_child=_after_fork_in_child)


class BufferedNormals:
    """``rng.standard_normal(shape)`` served from a buffer refilled ``chunk`` draws at a time.

    The values come in the same order as from ``rng`` directly (a generator's standard
    normal stream does not depend on how it is split into calls), so images get the same
    noise; a camera frame then costs a slice instead of a generator call. Only standard
    normals are served (camera noise is all the run draws).
    """

    def __init__(self, rng: np.random.Generator, chunk: int = 16384):
        self.rng = rng
        self.chunk = int(chunk)
        self._buf = np.empty(0)
        self._pos = 0

    def standard_normal(self, size=None) -> np.ndarray | float:
        if size is None:
            return float(self.standard_normal(1)[0])
        shape = (size,) if isinstance(size, (int, np.integer)) else tuple(size)
        n = math.prod(shape)
        pos, buf = self._pos, self._buf
        if pos + n <= len(buf):
            self._pos = pos + n
            return buf[pos:pos + n].reshape(shape)
        rest = buf[pos:]
        fresh = self.rng.standard_normal(max(self.chunk, n - len(rest)))
        self._buf, self._pos = fresh, n - len(rest)
        return np.concatenate((rest, fresh[:self._pos])).reshape(shape)

    def take(self, n: int) -> tuple[np.ndarray, int]:
        """The next ``n`` normals as ``(buffer, start)``: ``buffer[start:start + n]`` (for
        compiled code, which reads them in place). Same stream as :meth:`standard_normal`."""
        pos = self._pos
        if pos + n <= len(self._buf):
            self._pos = pos + n
            return self._buf, pos
        return self.standard_normal(n), 0


@dataclass
class Session:
    """What a Spinner talks to: the clock (and through it the car model), the camera, the
    car description, the noise generator, the run recorder (``add_data`` text) and the
    optional video recorder. Built by :mod:`simrunner.run.runner`."""

    clock: LockstepClock
    camera: "Camera"
    car: CarDescription
    rng: np.random.Generator
    recorder: RunRecorder | None = None
    video: "VideoRecorder | None" = None
    params: Mapping[str, ParamValue] = field(default_factory=dict)
    imager: "Imager | None" = None  # the physical camera (camera.model linescan / area)
    warnings: list[str] = field(default_factory=list)  # warn_once texts, for the result

    def __post_init__(self) -> None:
        self.params_read: set[str] = set()  # names asked for with Spinner.param
        self.noise_rng = BufferedNormals(self.rng)  # what images draw their noise from
        self.record_text = self.recorder is not None and self.recorder.record_text
        self._token: contextvars.Token | None = None
        self.thread_id: int | None = None  # the thread running main (set by activate)
        self._warned: set[str] = set()
        self.exposure_s = float(self.car.camera.exposure_s)  # set_exposure's value
        self.exposure_before: tuple[int, float] | None = None  # (frame, the exposure it had): set_exposure at it
        self.exposure_next: float | None = None  # set_exposure(next_frame=True)'s value, loaded at the next boundary
        self.exposure_loaded_at: int | None = None  # the boundary (frame) it was loaded at last
        self.free_running = False  # camera_free_running(): a linescan frame period is the exposure
        self.pixy2_tracker = None  # the Pixy2's line tracker (simrunner.run.pixy2), made on first use
        self.pixy2_frame: int | None = None  # the last frame the Pixy2 returned features of
        self.ranging = None  # the range sensors (simrunner.sensors.ranging), made on first use
        self.encoders = None  # the wheel encoders (simrunner.sensors.imu), made on first use
        self.imu = None       # the IMU (simrunner.sensors.imu), made on first use
        self.imu_truth = None  # () -> what an ideal IMU reads now (CarSim.imu_reader at its place)
        self.imu_noise = None  # the IMU's ImuNoise, shared with the run log's copy (None: its own)
        self.seed = 0        # the run's seed (the range sensors' noise)
        self.mcu = None      # the controller's own time (simrunner.run.mcu.McuTime), or None
        self.surface_z_m = 0.0
        self.clock.warn = self.warn_once  # (held interrupts: simrunner.run.clock)

    def activate(self) -> None:
        """Make this the session ``Spinner()`` attaches to in this context (and thread)."""
        self._token = _current_session.set(self)
        self.thread_id = _get_ident()

    def has_warned(self, key: str) -> bool:
        """A warning with ``key`` was added already (:meth:`warn_once`)."""
        return key in self._warned

    def warn_once(self, key: str, text: str) -> None:
        """Add warning ``text`` unless one with ``key`` was added already."""
        if key not in self._warned:
            self._warned.add(key)
            self.warnings.append(text)

    def deactivate(self) -> None:
        if self._token is not None:
            _current_session.reset(self._token)
            self._token = None


def _identity_speed(speed: float, angle: float) -> float:
    return speed


def _identity_angle(speed: float, angle: float) -> float:
    return angle


def _finite(method: str, name: str, value: Any) -> float:
    if type(value) is float and value - value == 0.0:  # fast path: a finite float
        return value
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CommandError(f"{method}({name}={value!r}): expected a number") from None
    if not math.isfinite(v):
        raise CommandError(f"{method}({name}={value!r}): expected a finite number")
    return v


def _norm_out(call: str, norm: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise CommandError(f"{call}: {norm} returned {value!r}, expected a number") from None
    if not math.isfinite(v):
        raise CommandError(f"{call}: {norm} returned {value!r}, expected a finite number")
    return v


class Spinner:
    """The controller's handle on the simulated car (thesis Appendix A.2).

    ``Spinner(speed_norm=None, speed_denorm=None, turn_norm=None, diff_norm=None)`` inside a
    running controller attaches to the running simulation (like the thesis's constructor);
    ``main(spinner)`` already gets one, which :meth:`configure` adapts.
    """

    LINE_ROW: int = CarDescription().camera.default_row

    def __init__(self, speed_norm: NormFn | None = None, speed_denorm: NormFn | None = None,
                 turn_norm: NormFn | None = None, diff_norm: NormFn | None = None, *,
                 session: Session | None = None):
        if session is None:
            session = _current_session.get()
            if session is None:
                from simrunner.run.faults import orphan_call

                message = orphan_call("__init__")
                if message is not None:
                    raise CommandError(message)
                raise SimError("Spinner() needs a running simulation: run the controller with "
                               "`simrunner drive FILE` (it calls main(spinner))")
        self._s = session
        self._owner = session.thread_id if session.thread_id is not None else _get_ident()
        self._vmax = 1.0 if session.car.drive.command == "duty" else session.car.drive.max_speed_mps
        self._clock = session.clock
        self._step_one = session.clock.step_one  # one physics step (every sensor call)
        self._sim = session.clock.sim
        self._line_image = session.camera.line_image  # render_row + add_noise in one call
        cam = session.car.camera
        self.line_row: int = cam.default_row
        self.image_shape: tuple[int, int] = (cam.height_px, cam.width_px)
        self.wheelbase_m: float = session.car.chassis.wheelbase_m
        self._speed = 0.0  # last speed and angle in the controller's units
        self._angle = 0.0
        self._speed_mps = 0.0
        self._steer_rad = 0.0
        self.speed_norm: NormFn = _identity_speed
        self.speed_denorm: NormFn = _identity_speed
        self.turn_norm: NormFn = _identity_angle
        self.diff_norm: NormFn = self.default_diff_norm
        self.configure(speed_norm, speed_denorm, turn_norm, diff_norm)
        if session.mcu is not None:  # --mcu-time: each call first lets the controller's time pass
            from simrunner.run.mcu import charge_calls

            charge_calls(self, session.mcu)  # (every public method, camelCase too, but the exempt)

    # -- configuration ---------------------------------------------------------------
    def default_diff_norm(self, speed_mps: float, steer_rad: float) -> float:
        """Thesis eq. 5.2/5.3: R = L / sin(delta), omega = v / R."""
        return speed_mps * math.sin(steer_rad) / self.wheelbase_m

    def configure(self, speed_norm: NormFn | None = None, speed_denorm: NormFn | None = None,
                  turn_norm: NormFn | None = None, diff_norm: NormFn | None = None) -> "Spinner":
        """Replace the given norm functions (``None`` keeps the current one); returns self."""
        for name, fn in (("speed_norm", speed_norm), ("speed_denorm", speed_denorm),
                         ("turn_norm", turn_norm), ("diff_norm", diff_norm)):
            if fn is not None:
                if not callable(fn):
                    raise SimError(f"configure({name}={fn!r}): expected a function (speed, angle)")
                setattr(self, name, fn)
        return self

    # -- commands --------------------------------------------------------------------
    def _send(self, method: str, speed: float, angle: float, set_speed: bool,
              set_steer: bool) -> None:
        clock = self._clock
        if clock.finished is not None:
            clock.check()
        if _get_ident() != self._owner:
            raise self._foreign(method)
        if set_steer:
            v = self.turn_norm(speed, angle)
            if not (type(v) is float and v - v == 0.0):  # not a finite float: check, convert
                v = _norm_out(f"{method}(speed={speed!r}, angle={angle!r})", "turn_norm", v)
            self._steer_rad = v
        if set_speed:
            v = self.speed_norm(speed, angle)
            if not (type(v) is float and v - v == 0.0):
                v = _norm_out(f"{method}(speed={speed!r}, angle={angle!r})", "speed_norm", v)
            if not -self._vmax <= v <= self._vmax:
                self._capped(v)
            self._speed_mps = v
        yaw = self.diff_norm(self._speed_mps, self._steer_rad)
        if not (type(yaw) is float and yaw - yaw == 0.0):
            yaw = _norm_out(f"{method}(speed={speed!r}, angle={angle!r})", "diff_norm", yaw)
        clock.command(self._speed_mps, self._steer_rad, yaw, not set_speed)

    def _foreign(self, method: str) -> CommandError:
        """A call from a thread that does not run ``main``: end the run (controller_error)."""
        from simrunner.run.faults import foreign_thread_message

        err = CommandError(foreign_thread_message(method))
        err.ends_the_run = True  # said as the run's outcome: the thread's traceback is not printed
        return self._fail(err)

    def _capped(self, speed_mps: float) -> None:
        from simrunner.run.faults import caller_location

        where = caller_location(3)
        at = f"{' at ' + where if where else ''} (t = {self._clock.time_s:.2f} s)"
        if self._s.car.drive.command == "duty":
            text = (f"duty command {speed_mps:g}{at} is beyond -1..1 (drive.command = duty: "
                    f"set_speed takes a duty after speed_norm): the motors take at most "
                    f"full duty (warned once)")
        else:
            text = (f"speed command {speed_mps:g} m/s{at} is beyond the car's maximum "
                    f"{self._vmax:g} m/s (drive.max_speed_mps): the car drives at most that "
                    f"(warned once)")
        self._s.warn_once("speed_cap", text)

    def _fail(self, err: CommandError) -> CommandError:
        self._clock.finish("controller_error", str(err))
        return err

    def set_servo(self, angle: float, speed: float | None = None) -> None:
        """Steer. ``speed`` (default: the last ``set_speed`` value) only feeds ``turn_norm``."""
        try:
            a = _finite("set_servo", "angle", angle)
            s = self._speed if speed is None else _finite("set_servo", "speed", speed)
            self._angle = a
            self._send("set_servo", s, a, False, True)
        except CommandError as err:
            raise self._fail(err) from None

    def set_speed(self, speed: float, angle: float | None = None) -> None:
        """Drive. ``angle`` (default: the last ``set_servo`` value) only feeds ``speed_norm``;
        the differential uses the commanded speed and steering."""
        try:
            s = _finite("set_speed", "speed", speed)
            a = self._angle if angle is None else _finite("set_speed", "angle", angle)
            self._speed = s
            self._send("set_speed", s, a, True, False)
        except CommandError as err:
            raise self._fail(err) from None

    def set_motors(self, left: float, right: float) -> None:
        """The duty (-1..1) of the left and the right rear motor (the car file's ``drive.command
        = "duty"``; the differential is then yours, as on the car). A speed-commanded car takes
        their mean as a share of its top speed. Later steering commands keep them; a speed
        command ends them. No time passes."""
        try:
            l_duty = _finite("set_motors", "left", left)
            r_duty = _finite("set_motors", "right", right)
        except CommandError as err:
            raise self._fail(err) from None
        clock = self._clock
        if clock.finished is not None:
            clock.check()
        if _get_ident() != self._owner:
            raise self._foreign("set_motors")
        if self._s.car.drive.command == "duty":
            clock.motors(l_duty, r_duty)
            return
        # a speed-commanded car: the mean duty's share of the top speed, as a speed command
        mean = 0.5 * (min(max(l_duty, -1.0), 1.0) + min(max(r_duty, -1.0), 1.0))
        self._speed_mps = mean * self._s.car.drive.max_speed_mps
        yaw = self.diff_norm(self._speed_mps, self._steer_rad)
        if not (type(yaw) is float and yaw - yaw == 0.0):
            yaw = _norm_out(f"set_motors({left!r}, {right!r})", "diff_norm", yaw)
        clock.command(self._speed_mps, self._steer_rad, yaw)

    def set_speed_and_servo(self, speed: float, angle: float) -> None:
        """Drive and steer at once (recommended by the thesis)."""
        try:
            s = speed if type(speed) is float and speed - speed == 0.0 else _finite(
                "set_speed_and_servo", "speed", speed)
            a = angle if type(angle) is float and angle - angle == 0.0 else _finite(
                "set_speed_and_servo", "angle", angle)
            self._speed, self._angle = s, a
            self._send("set_speed_and_servo", s, a, True, True)
        except CommandError as err:
            raise self._fail(err) from None

    # -- sensors (these let time pass) ---------------------------------------------------
    def get_image(self, line: int = -1, add_noise: bool = True) -> np.ndarray:
        """Wait for the next camera frame and return it: ``(H, W)`` uint8 for ``line=-1``,
        else row ``line`` as ``(1, W)`` uint8. Noise (``add_noise``) from the run's seed."""
        h = self.image_shape[0]
        if type(line) is not int or not -1 <= line < h:
            if isinstance(line, bool) or not isinstance(line, (int, np.integer)) or not -1 <= line < h:
                raise self._fail(CommandError(
                    f"get_image(line={line!r}): expected -1 (whole image) or a row 0..{h - 1}"))
            line = int(line)
        if _get_ident() != self._owner:
            raise self._foreign("get_image")
        clock, session = self._clock, self._s
        if clock.in_interrupt:
            raise self._fail(CommandError(f"get_image({line}) inside an interrupt handler: {_NO_WAIT}"))
        clock.advance_to_next_frame()
        img = self._frame_now(line, add_noise)
        if session.video is not None:
            session.video.note_image(img, line)
        return img

    def latest_image(self, line: int = -1, add_noise: bool = True,
                     after_frame: int = -1) -> tuple[int, np.ndarray | None]:
        """The camera's latest frame - the last frame boundary passed - without waiting: ``(its
        index, its image)`` when it is newer than ``after_frame``, else ``(its index, None)``
        (frames count from 0, the start). No simulated time passes (a handler may call it): what a
        camera read-out running beside the program sees, as a kit's camera interrupt (the TFC
        kit's); :meth:`get_image` waits for the next frame."""
        h = self.image_shape[0]
        if isinstance(line, bool) or not isinstance(line, (int, np.integer)) or not -1 <= line < h:
            raise self._fail(CommandError(
                f"latest_image(line={line!r}): expected -1 (whole image) or a row 0..{h - 1}"))
        if _get_ident() != self._owner:
            raise self._foreign("latest_image")
        clock = self._clock
        if clock.frame_index <= after_frame:
            return clock.frame_index, None
        img = self._frame_now(int(line), add_noise, clock.boundary_pose, True)
        if self._s.video is not None:
            self._s.video.note_image(img, int(line))
        return clock.frame_index, img

    def _frame_now(self, line: int, add_noise: bool, pose=None, latest: bool = False) -> np.ndarray:
        """The camera's image (row ``line``, or all for -1) at ``pose`` (None: the clock's now);
        ``latest``: the last boundary's frame, read after it (its exposure the one it had)."""
        session = self._s
        pose = self._clock.pose() if pose is None else pose
        imager = session.imager
        if imager is not None:  # the physical camera (simrunner.sensors.imaging)
            exposure_s = session.exposure_s
            before = session.exposure_before
            frame = self._clock.frame_index
            if before is not None and before[0] == frame and (latest or session.exposure_loaded_at == frame):
                exposure_s = before[1]  # set since this frame ended (loaded at its end): the next one has it
            return self._expose(imager, pose, line, add_noise, exposure_s,
                                self._clock.boundary_twist if latest else None)
        if line >= 0:  # one call (simrunner.sensors.line_row)
            return self._line_image(pose, line, session.noise_rng if add_noise else None)
        cam = session.camera
        img = cam.render(pose)
        return cam.add_noise(img, session.noise_rng) if add_noise else img

    # -- the Pixy2 (simrunner.run.pixy2) ------------------------------------------------
    def pixy2(self) -> "Pixy2":
        """The car's Pixy2 (its Arduino/C++ API: ``pixy.line.getMainFeatures()``, ...;
        docs/pixy2.md). Its frames are this camera's; the car needs a Pixy2 camera
        (``--car examples/pixy2_car.toml``)."""
        from simrunner.run.pixy2 import Pixy2

        return Pixy2(self)

    def _next_pixy_frame(self, wait: bool) -> bool:
        """Process the next Pixy2 frame (module docstring of :mod:`simrunner.run.pixy2`);
        False when polling (``wait`` False) found no new frame."""
        if _get_ident() != self._owner:
            raise self._foreign("pixy2")
        s, clock = self._s, self._clock
        if s.pixy2_frame == clock.frame_index:
            if wait:
                clock.advance_to_next_frame()
            else:
                if not clock.in_interrupt:  # (a poll is a read: no time passes in a handler)
                    clock.advance(1)
                if s.pixy2_frame == clock.frame_index:
                    return False
        s.pixy2_frame = clock.frame_index
        img = self._frame_now(-1, True)
        tracker = s.pixy2_tracker
        tracker.process(img)
        if s.video is not None:
            s.video.note_image(img, -1)
            s.video.note_pixy2(tracker.all, tracker.vector_index, tracker.w, tracker.h)
        return True

    def _expose(self, imager: "Imager", pose, line: int, add_noise: bool,
                exposure_s: float, twist=None) -> np.ndarray:
        """The physical camera's frame just read: integrated over the exposure in force,
        blurred by the car's motion (``twist``: the motion kept at the frame's boundary for a
        frame read later; None: the car's now), noisy unless ``add_noise`` is False."""
        sim, session = self._sim, self._s
        if twist is None and imager.spec.motion_blur_samples > 1:
            twist = (sim.speed_mps, sim.lateral_speed_mps, sim.yaw_rate_radps)
        elif imager.spec.motion_blur_samples <= 1:
            twist = None
        kw = dict(exposure_s=exposure_s, twist=twist, frame_index=self._clock.frame_index,
                  normals=session.noise_rng if add_noise else None)
        return imager.line(pose, line, **kw) if line >= 0 else imager.frame(pose, **kw)

    def set_exposure(self, seconds: float, *, next_frame: bool = False) -> None:
        """Set the camera's exposure (integration) time in seconds (``camera.exposure_s`` at
        the start). A ``linescan`` camera's frames are then ``seconds + readout_s`` apart,
        from the frame in progress on (as an SI pulse timer the code reprograms); an ``area``
        camera keeps its frame rate and exposes at most one frame period; the ``ideal``
        camera stores the value and ignores it. No time passes.

        ``next_frame``: from the next frame on instead, as a timer's period register written
        while the timer runs loads at its next expiry (a kit's: the KL25's PIT LDVAL, its TPM
        MOD): the frame in progress keeps its period and its exposure; at its end the exposure
        becomes ``seconds`` and the frame after it is integrated over it (and, ``linescan``, is
        that long). Of several such calls before that end the last wins (one register); a call
        without ``next_frame`` drops a value waiting to load. :meth:`get_exposure` gives the
        exposure in force: the new one once loaded. C: ``spinner_set_exposure_next_frame``."""
        s = _finite("set_exposure", "seconds", seconds)
        cam = self._s.car.camera
        lo, hi = cam.exposure_range_s()
        if cam.model == "area":
            hi = 1.0 / cam.fps_hz
        if not lo <= s <= hi:
            raise self._fail(CommandError(
                f"set_exposure(seconds={seconds!r}): expected {lo:g} to {hi:g} s"
                + (f" (an area camera exposes within its frame of 1 / {cam.fps_hz:g} Hz)"
                   if cam.model == "area" else "")))
        if _get_ident() != self._owner:
            raise self._foreign("set_exposure")
        session, clock = self._s, self._clock
        if next_frame:
            session.exposure_next = s  # (one register: the last write before the boundary wins)
            clock.boundary_hook = self._load_exposure
            return
        if session.exposure_next is not None:
            session.exposure_next = None
            clock.boundary_hook = None
        self._apply_exposure(s)

    def _apply_exposure(self, s: float) -> None:
        """The exposure ``s`` from the frame in progress on (``s`` validated)."""
        session, clock = self._s, self._clock
        if session.exposure_before is None or session.exposure_before[0] != clock.frame_index:
            session.exposure_before = (clock.frame_index, session.exposure_s)  # the latest frame's
        session.exposure_s = s
        cam = session.car.camera
        if cam.model == "linescan":
            clock.set_frame_period(cam.frame_period_s(s, free_running=session.free_running))

    def _load_exposure(self) -> None:
        """At a frame boundary (the clock's ``boundary_hook``): the exposure ``set_exposure(...,
        next_frame=True)`` left waiting loads, for the frame that starts here; the frame that
        ended keeps the one it had. One equal to the exposure in force changes nothing (the
        timer's period goes on, its frames where they were)."""
        session = self._s
        s, session.exposure_next = session.exposure_next, None
        if s is None or s == session.exposure_s:
            return
        self._apply_exposure(s)
        session.exposure_loaded_at = self._clock.frame_index

    def camera_free_running(self) -> None:
        """The camera's SI pulses come from a free-running timer (a kit whose board driver reads
        each image out while the next integrates, as the FRDM-TFC library's PIT): a ``linescan``
        camera's frames are then one exposure apart (not exposure + ``readout_s``), from the
        frame in progress on; each is still integrated over the exposure that ends ``readout_s``
        before it. Other models are unchanged. No time passes."""
        if _get_ident() != self._owner:
            raise self._foreign("camera_free_running")
        session, cam = self._s, self._s.car.camera
        if session.free_running:
            return
        session.free_running = True
        if cam.model == "linescan":
            self._clock.set_frame_period(cam.frame_period_s(session.exposure_s, free_running=True))

    def get_exposure(self) -> float:
        """The exposure time in seconds (:meth:`set_exposure`). No time passes."""
        return self._s.exposure_s

    def get_speed(self) -> float:
        """Current speed along the car's x (after one physics step), through ``speed_denorm``."""
        if _get_ident() != self._owner:
            raise self._foreign("get_speed")
        self._step_one()
        return float(self.speed_denorm(self._sim.speed_mps, self._angle))

    def get_distance(self, name: str) -> float:
        """The reading of range sensor ``name`` (the car file's ``[range_sensors.NAME]``): metres
        to the nearest object standing on the track, ``inf`` when none is in range
        (:mod:`simrunner.sensors.ranging`), after one physics step."""
        if _get_ident() != self._owner:
            raise self._foreign("get_distance")
        ranging = self._ranging()
        self._step_one()
        s = self._s
        return ranging.read(str(name), self._clock.time_s, self._clock.pose(), s.camera.solids, s.surface_z_m)

    def _ranging(self):
        s = self._s
        if s.ranging is None:
            from simrunner.sensors.ranging import RangeSensors

            s.ranging = RangeSensors(s.car.range_sensors, s.seed)
        return s.ranging

    def get_scan(self, name: str) -> np.ndarray:
        """The scan of lidar ``name`` (a ``[range_sensors.NAME]`` with ``kind = "lidar"``): one
        reading per ray (m, ``inf`` where nothing is in range), in the order of
        :meth:`scan_angles`, after one physics step (:mod:`simrunner.sensors.ranging`)."""
        if _get_ident() != self._owner:
            raise self._foreign("get_scan")
        ranging = self._ranging()
        self._step_one()
        s = self._s
        return ranging.scan(str(name), self._clock.time_s, self._clock.pose(), s.camera.solids, s.surface_z_m)

    def scan_angles(self, name: str) -> np.ndarray:
        """The directions of range sensor ``name``'s rays: rad in the car frame, + = left of
        straight ahead (from the car file; no time passes)."""
        return self._ranging().angles(str(name))

    def get_encoder(self, wheel) -> int:
        """The count of the encoder on ``wheel`` (``"FL"``, ``"FR"``, ``"RL"``, ``"RR"`` or 0..3;
        the car file's ``[encoders]``): whole counts since the start, signed for quadrature
        decoding (:mod:`simrunner.sensors.imu`), after one physics step."""
        if _get_ident() != self._owner:
            raise self._foreign("get_encoder")
        s = self._s
        if s.encoders is None:
            from simrunner.sensors.imu import Encoders

            s.encoders = Encoders(s.car.encoders)
        self._step_one()
        return s.encoders.read(wheel, self._sim)

    def _imu(self, call: str) -> tuple[float, ...]:
        if _get_ident() != self._owner:
            raise self._foreign(call)
        s = self._s
        if s.imu is None:
            from simrunner.sensors.imu import Imu

            s.imu = Imu(s.car.imu, s.seed, s.imu_noise)
            s.imu_truth = None if s.car.imu is None else self._sim.imu_reader((s.car.imu.x_m, s.car.imu.y_m, s.car.imu.z_m))
        self._step_one()
        return s.imu.sample(call, self._clock.time_s, s.imu_truth)

    def get_gyro(self) -> tuple[float, float, float]:
        """The IMU's angular rates about the car's x, y, z axes (rad/s; z: + = turning left),
        after one physics step: the car file's ``[imu]`` with its noise, bias, range and
        resolution (:mod:`simrunner.sensors.imu`)."""
        return self._imu("get_gyro")[:3]

    def get_accel(self) -> tuple[float, float, float]:
        """The IMU's accelerometer along the car's x, y, z axes (m/s^2; the specific force: at
        rest +9.81 up), after one physics step (:mod:`simrunner.sensors.imu`)."""
        return self._imu("get_accel")[3:]

    def get_position(self) -> tuple[float, float, float]:
        """World position ``(x, y, z)`` in metres of the car frame origin (rear-axle midpoint
        on the ground), after one physics step."""
        if _get_ident() != self._owner:
            raise self._foreign("get_position")
        self._step_one()
        p = self._clock.pose()
        return (p.x_m, p.y_m, float(self._sim.z_m))

    def get_time(self) -> float:
        """Simulated time in seconds, after one physics step (busy-wait loops finish)."""
        if _get_ident() != self._owner:
            raise self._foreign("get_time")
        self._step_one()
        return self._clock.time_s

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` of simulated time pass (``ceil(seconds / dt)`` steps, at least 1);
        stands in for ``usleep``."""
        try:
            s = _finite("sleep", "seconds", seconds)
            if s < 0:
                raise CommandError(f"sleep(seconds={seconds!r}): expected >= 0")
        except CommandError as err:
            raise self._fail(err) from None
        if _get_ident() != self._owner:
            raise self._foreign("sleep")
        if self._clock.in_interrupt:
            raise self._fail(CommandError(f"sleep({seconds!r}) inside an interrupt handler: {_NO_WAIT}"))
        n = max(1, math.ceil(s / self._clock.dt_s - 1e-9))
        self._clock.advance(n)

    def every(self, period_s: float, handler: Callable[[], Any]) -> None:
        """Call ``handler()`` every ``period_s`` seconds of simulated time from now, as a timer
        interrupt would (the first call one period from now): it interrupts the main code in
        its next waiting call (:mod:`simrunner.run.clock`, Interrupts). Inside the handler no time
        passes: sensor reads give the state at its time, commands act from the next physics step,
        and a wait (``get_image``, ``sleep``) is an error. Handlers due together run in the order
        they were set up. C: ``spinner_every``; firmware: ``simrunner drive --isr NAME@HZ``."""
        try:
            p = _finite("every", "period_s", period_s)
            if not MIN_INTERRUPT_PERIOD_S <= p:
                raise CommandError(f"every(period_s={period_s!r}): expected at least "
                                   f"{MIN_INTERRUPT_PERIOD_S:g} s (a {1 / MIN_INTERRUPT_PERIOD_S:g} Hz timer)")
            if not callable(handler):
                raise CommandError(f"every(period_s={period_s!r}, handler={handler!r}): expected a function")
        except CommandError as err:
            raise self._fail(err) from None
        if _get_ident() != self._owner:
            raise self._foreign("every")
        self._clock.add_interrupt(p, handler)

    def stop_every(self, handler: Callable[[], Any]) -> None:
        """Stop the timer interrupts set up by :meth:`every` with ``handler`` (the same function
        object): it is not called again, not even when due at this step. C: ``spinner_stop_every``."""
        if _get_ident() != self._owner:
            raise self._foreign("stop_every")
        self._clock.remove_interrupt(handler)

    def disable_interrupts(self) -> None:
        """Mask the timer interrupts, as ``__disable_irq()`` sets the Cortex-M's PRIMASK: a handler
        that falls due meanwhile is held pending and runs once (however often it fell due) at
        :meth:`enable_interrupts`. A flag, not a count: a second call changes nothing. Allowed in
        a handler (later handlers are then held until the unmask). C: ``spinner_disable_interrupts``."""
        if _get_ident() != self._owner:
            raise self._foreign("disable_interrupts")
        if self._clock.masked:
            return
        frame = sys._getframe(1)  # the caller's line, for the warning of interrupts left disabled
        while frame is not None and frame.f_code.co_filename.startswith(_RUN_DIR):
            frame = frame.f_back  # (the --mcu-time wrapper)
        where = None if frame is None else f"{frame.f_code.co_filename}:{frame.f_lineno}"
        self._clock.mask(where=lambda: where)

    def enable_interrupts(self) -> None:
        """Unmask the timer interrupts (``__enable_irq()``): the handlers held pending run now, in
        the order they were set up, before this call returns (no time passes); in a handler, after
        it returns. C: ``spinner_enable_interrupts``."""
        if _get_ident() != self._owner:
            raise self._foreign("enable_interrupts")
        self._clock.unmask()

    def interrupts_disabled(self) -> bool:
        """Whether :meth:`disable_interrupts` masks the timer interrupts now (no time passes).
        C: ``spinner_interrupts_disabled``."""
        return self._clock.masked

    # -- parameters ------------------------------------------------------------------------
    def param(self, name: str, default: Any = None) -> Any:
        """The run's ``--param NAME=VALUE`` converted to the type of ``default`` (int, float,
        bool, str; None: as parsed), or ``default`` when it was not given. A value that does
        not convert ends the run as a controller error naming it. Does not let time pass."""
        s = self._s
        s.params_read.add(name)
        if name not in s.params:
            return default
        try:
            return convert(name, s.params[name], default)
        except CommandError as err:
            raise self._fail(err) from None

    # -- debugging data ------------------------------------------------------------------
    @property
    def recording(self) -> bool:
        """True when :meth:`add_data` text is kept: a debug video or a run-log CSV (its
        ``data_text`` column) is written. A controller may skip formatting text otherwise."""
        return self._s.video is not None or self._s.record_text

    def add_data(self, data: Sequence[str] | str | np.ndarray) -> None:
        """Add to the debug video: a list of text lines (or one string), shown in the right
        column; or a processed image line (``(W,)``, ``(1, W)`` or ``(k, W)`` array), shown
        stretched under the camera line. Data added during one frame replaces the previous
        frame's; it stays on screen until replaced."""
        s = self._s
        if _get_ident() != self._owner:
            raise self._foreign("add_data")
        if type(data) is list and s.video is None:
            try:  # the common case without a video: all str (join checks)
                "".join(data)
            except TypeError:
                pass  # not all str: the checks below raise
            else:
                if s.record_text:
                    s.recorder.text(data)
                return
        if isinstance(data, np.ndarray):
            arr = data
            if arr.ndim == 1:
                arr = arr.reshape(1, -1)
            if arr.ndim != 2 or arr.shape[1] == 0:
                raise self._fail(CommandError(
                    f"add_data(array of shape {data.shape}): expected an image line (W,) or (k, W)"))
            if s.video is not None:
                s.video.add_lines(arr)
            return
        if isinstance(data, str):
            lines = [data]
        elif isinstance(data, (list, tuple)) and all(isinstance(x, str) for x in data):
            lines = list(data)
        else:
            raise self._fail(CommandError(
                f"add_data({type(data).__name__}): expected a list of str or a numpy image line"))
        if s.record_text:
            s.recorder.text(lines)
        if s.video is not None:
            s.video.add_text(lines)

    def add_noise(self, img: np.ndarray) -> np.ndarray:
        """Add camera noise to ``img`` in place (when writable) and return it."""
        noisy = self._s.camera.add_noise(np.asarray(img), self._s.noise_rng)
        if isinstance(img, np.ndarray) and img.flags.writeable and img.shape == noisy.shape:
            img[...] = noisy
            return img
        return noisy

    # -- camelCase aliases (the thesis's C++ names) --------------------------------------
    setServo = set_servo
    setSpeed = set_speed
    setSpeedAndServo = set_speed_and_servo
    getImage = get_image
    getSpeed = get_speed
    getPosition = get_position
    getDistance = get_distance
    getTime = get_time
    addData = add_data
    addNoise = add_noise
    setExposure = set_exposure
    getExposure = get_exposure
    cameraFreeRunning = camera_free_running
