"""Running a C/C++ controller: its Spinner calls as messages, answered by the Python Spinner.

:class:`~simrunner.run.native.controller.NativeController` is a ``main(spinner)`` callable
(what the runner calls for every controller), so a C program runs on the same lockstep clock,
judging, telemetry and video as a Python one. A program simrunner built runs in this process
by default (:mod:`.inproc`, the same messages handed over by a context switch). Otherwise - ``--isolate``, or a
prebuilt library - calling it starts the host program (``host/spinner_host.c``) with the
controller's shared library; the host calls the program's own ``main`` and sends each
Spinner call to this process over a pipe, which answers it with the Python
:class:`Spinner` - the simulation advances inside those answers, exactly as for a Python
controller. The rest of this docstring is about that child process.

The controller is isolated: a crash, an abort or a stack overflow kills the child only. The
child reports the fault with its raw backtrace; :mod:`.symbolize` turns it into file:line
and the run ends with ``controller_error`` (a :class:`ControllerError` with the C backtrace)
after everything recorded so far. A loop that never calls the Spinner is stopped by the
runner's watchdog; the child is then asked (SIGUSR1) where it is. The child's stdout and
stderr are the terminal's.

Speed: a camera frame is one round trip (the host queues commands and debug data until the
next waiting call), answered from one read. The child is kept on the CPU the simulator runs
on (its affinity follows the simulator's CPU): the two take turns, so nothing runs in parallel
anyway, and a hand-off on one CPU needs no wake-up of another, idle one (on a quiet virtual
machine that cost ~60 us a frame). Threads the C program starts share that CPU.
"""
from __future__ import annotations

import dataclasses
import math
import os
import select
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

from simrunner.errors import ControllerError, ControllerFileError, RunFinished, Stalled
from simrunner.run.mcu import UNCHARGED_REQUESTS
from simrunner.run.native.build import NativeProgram, missing_function, misspelt_function
from simrunner.run.native.symbolize import IN_CONSTRUCTOR
from simrunner.run.watchdog import native_stall_hint

# request ops (host -> simulator), reply status (simulator -> host): spinner_host.c
OP_CMD, OP_TEXT, OP_LINE, OP_IMAGE, OP_SPEED, OP_POSITION, OP_TIME, OP_SLEEP, OP_NOISE, \
    OP_PARAM, OP_FAULT, OP_SET_EXPOSURE, OP_GET_EXPOSURE, OP_PIXY_FEATURES, OP_PIXY_SET, \
    OP_PIXY_PROG, OP_DISTANCE, OP_SCAN, OP_ENCODER, OP_IMU, OP_CPU, OP_MOTORS, OP_EVERY, \
    OP_ISR_DONE, OP_EVERY_STOP, OP_WARN, OP_LATEST_IMAGE, OP_NOW, OP_IRQ_MASK, OP_IRQ_MASK_WAIT, \
    OP_EVERY_UNPEND, OP_PEND, OP_PEND_WAIT, OP_EVERY_PENDING, OP_EXIT_AT, OP_FREE_RUNNING, \
    OP_SET_EXPOSURE_NEXT, OP_EVERY_STOP_LATCHED, OP_NOW_UNCHARGED = range(1, 40)
ST_OK, ST_FINISHED, ST_ERROR, ST_WHERE, ST_ISR = 0, 1, 2, 3, 4
EXIT_NO_MAIN, EXIT_NOT_LOADED = 72, 71
EXIT_AT_LOAD = 0x80  # OP_EXIT_AT's call byte: the exit was in a constructor (spinner_host.c)
LOAD_ERROR_FD_ENV = "SPINNER_LOAD_ERROR_FD"  # where the host writes the loader's error (not stderr)
_HDR = struct.Struct("<II")
_OK_EMPTY = _HDR.pack(ST_OK, 0)
_CMD = struct.Struct("<3d")
_D = struct.Struct("<d")
_3D = struct.Struct("<3d")
_2I = struct.Struct("<2i")
_FRAME = struct.Struct("<II3dII2i")  # OP_CMD {speed, steer, yaw} then OP_IMAGE {line, noise}
EXIT_WAIT_S = 5.0


def _sensor_spec(car) -> tuple[float, float, float, float]:
    """The car's encoders and IMU as the program's INIT message gives them (spinner_encoder_lines,
    spinner_has_imu): the wheels with an encoder (a mask, bit i = wheel i: FL, FR, RL, RR), its
    lines per revolution, the counts per line of spinner_get_encoder (4, 2, 1; 0: one channel
    without direction) and 1.0 when the car has an IMU."""
    from simrunner.sensors.imu import ON, PER_LINE, WHEELS

    enc, mask, lines, per_line = car.encoders, 0, 0, 0
    if enc is not None:
        mask = sum(1 << WHEELS.index(w) for w in ON[enc.wheels])
        lines, per_line = enc.lines_per_rev, 0 if enc.counting == "single" else PER_LINE[enc.counting]
    return float(mask), float(lines), float(per_line), 0.0 if car.imu is None else 1.0


class _ChildGone(Exception):
    """The request pipe reached its end (the child exited or died)."""


_PASS = (RunFinished, ControllerError, _ChildGone, KeyboardInterrupt)  # not a refused call
# the requests the program waits in for a reply (spinner_host.c: call()); the others are queued
_WAITING = frozenset((OP_IMAGE, OP_SPEED, OP_POSITION, OP_TIME, OP_SLEEP, OP_NOISE, OP_PARAM, OP_FAULT,
                      OP_SET_EXPOSURE, OP_GET_EXPOSURE, OP_PIXY_FEATURES, OP_PIXY_SET, OP_PIXY_PROG,
                      OP_DISTANCE, OP_SCAN, OP_ENCODER, OP_IMU, OP_LATEST_IMAGE, OP_NOW, OP_IRQ_MASK_WAIT,
                      OP_PEND_WAIT, OP_EVERY_PENDING, OP_FREE_RUNNING, OP_SET_EXPOSURE_NEXT, OP_NOW_UNCHARGED))
# the requests --mcu-time does not charge (simrunner.run.mcu, the reason of each); _handle charges the rest
_UNCHARGED = frozenset(globals()[name] for name in UNCHARGED_REQUESTS)


class _Child:
    """A started host process and the simulator's ends of its two pipes. Started before the
    run (process start and library loading are not run time); the program's ``main`` waits
    for the run's first message."""

    def __init__(self, host: Path, program: NativeProgram, args: tuple[str, ...]):
        sys.stdout.flush()
        sys.stderr.flush()
        req_r, req_w = os.pipe()
        rep_r, rep_w = os.pipe()
        err_r, err_w = os.pipe()  # the loader's error, if the library cannot be loaded
        try:
            self.proc = subprocess.Popen(
                [str(host), str(program.library), str(req_w), str(rep_r), program.name, *args],
                pass_fds=(req_w, rep_r, err_w), close_fds=True,
                env={**os.environ, LOAD_ERROR_FD_ENV: str(err_w)})
        except OSError as exc:
            for fd in (req_r, req_w, rep_r, rep_w, err_r, err_w):
                os.close(fd)
            raise ControllerFileError(f"{host}: cannot start the controller ({exc})") from None
        for fd in (req_w, rep_r, err_w):
            os.close(fd)
        self.rfd, self.wfd, self.err_fd = req_r, rep_w, err_r

    def load_error(self) -> str:
        """What the loader said when the host could not load the library (its exit status
        EXIT_NOT_LOADED; the process has ended: the pipe's other end is closed)."""
        chunks = []
        while self.err_fd >= 0 and (chunk := os.read(self.err_fd, 4096)):
            chunks.append(chunk)
        return b"".join(chunks).decode("utf-8", "replace").strip()

    def close(self) -> None:
        """Kill the process (if still running), reap it, close the pipes (idempotent)."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        for fd in (self.rfd, self.wfd, self.err_fd):
            try:
                os.close(fd)
            except OSError:
                pass
        self.rfd = self.wfd = self.err_fd = -1

    def __del__(self) -> None:  # an unused pre-started child (the run never started)
        if getattr(self, "rfd", -1) >= 0:
            self.close()


def _cpu_getter() -> Callable[[], int] | None:
    """The C library's ``sched_getcpu`` (the CPU the calling thread runs on), or None where
    it or ``os.sched_setaffinity`` is missing."""
    if not hasattr(os, "sched_setaffinity"):
        return None
    try:
        import ctypes

        fn = ctypes.CDLL(None).sched_getcpu
    except (OSError, AttributeError):
        return None
    fn.restype, fn.argtypes = ctypes.c_int, ()
    return fn


class _Session:
    """One run of the child: the pipes, the read buffer and the request loop."""

    def __init__(self, ctrl, spinner, child: _Child):  # ctrl: a controller.NativeController
        self.ctrl, self.spinner, self.child = ctrl, spinner, child
        self._setup_transport(child)
        self.name = ctrl.program.name
        self.yaw = 0.0
        spinner.configure(diff_norm=lambda v, d: self.yaw)  # the C side computes the yaw rate
        self._buf = b""
        self._pos = 0
        self._in_call = False  # the request handled is the one the program waits in (_WAITING)
        self._isrs: dict[int, Callable[[], None]] = {}  # the program's timer interrupts by slot
        self._latched: dict[int, Callable[[], None] | None] = {}  # stopped ones that kept a pending call
        self._last_mask: tuple[bytes, Callable[[], str | None] | None] = (b"", None)  # _mask_where's
        self._exit_at: str | None = None  # "exit(3) at main.c:91": where the program exited (OP_EXIT_AT)
        self._exit_status = 0  # that call's status as the process ends with it (0..255)
        self._mcu = spinner._s.mcu  # --mcu-time (simrunner.run.mcu): _handle charges the requests
        self._pixy = None  # the Pixy2 the program's pixy2_line.h calls talk to (made on first use)

    def _setup_transport(self, child: _Child) -> None:
        self.proc, self.rfd, self.wfd = child.proc, child.rfd, child.wfd
        self._getcpu, self._cpu = self.ctrl.getcpu, -1

    # -- reading ---------------------------------------------------------------------
    def _fill(self, need: int, deadline: float | None = None) -> None:
        """Make at least ``need`` unread bytes available; raises _ChildGone at the end."""
        chunks = [self._buf[self._pos:]]
        have = len(chunks[0])
        while have < need:
            if deadline is not None and not self._readable(deadline):
                raise _ChildGone()
            data = self._recv()
            chunks.append(data)
            have += len(data)
        self._buf, self._pos = b"".join(chunks), 0

    def _message(self, deadline: float | None = None) -> tuple[int, bytes]:
        """The next ``(op, payload)``, reading as needed (until ``deadline``, if given)."""
        buf, pos = self._buf, self._pos
        if len(buf) - pos < 8:
            self._fill(8, deadline)
            buf, pos = self._buf, 0
        op, n = _HDR.unpack_from(buf, pos)
        if len(buf) - pos < 8 + n:
            self._fill(8 + n, deadline)
            buf, pos = self._buf, 0
        start = pos + 8
        self._pos = start + n
        return op, buf[start:start + n]

    def _readable(self, deadline: float) -> bool:
        """Whether requests arrive before ``deadline`` (``time.monotonic()``)."""
        left = deadline - time.monotonic()
        return left > 0 and bool(select.select([self.rfd], [], [], left)[0])

    def _recv(self) -> bytes:
        """The next bytes of requests (what one read gives); raises _ChildGone at the end."""
        data = os.read(self.rfd, 1 << 16)
        if not data:
            raise _ChildGone()
        return data

    def _exchange(self, img: np.ndarray) -> bytes:
        """Answer an image call with ``img`` and return the next requests (as :meth:`_recv`:
        at least a byte; raises _ChildGone at the end)."""
        self._reply(_HDR.pack(ST_OK, img.size) + img.tobytes())
        return self._recv()

    def _reply(self, data: bytes) -> None:
        """Send a reply (it wakes the child) from the CPU the child is kept on."""
        getcpu = self._getcpu
        if getcpu is not None:
            cpu = getcpu()
            if cpu != self._cpu:
                self._follow(cpu)
        try:
            os.write(self.wfd, data)
        except BrokenPipeError:
            pass  # the child is gone: the next read says how

    def _follow(self, cpu: int) -> None:
        """Keep the child on ``cpu``, the simulator's (the two take turns, never run at once:
        a hand-off on one CPU needs no cross-CPU wake-up, which costs tens of us on a virtual
        machine whose other CPU sleeps). Stops following if the system refuses."""
        self._cpu = cpu
        try:
            os.sched_setaffinity(self.proc.pid, {cpu})
        except (OSError, ValueError):  # also cpu -1: sched_getcpu failed
            self._getcpu = None

    # -- the run ---------------------------------------------------------------------
    def run(self) -> None:
        s = self.spinner
        try:
            h, w = s.image_shape
            mcu = s._s.mcu  # --mcu-time measured: the program reports its own CPU time (OP_CPU)
            measured = mcu is not None and mcu.fixed_s is None
            if measured:
                mcu.reported = True
            isrs = self.ctrl.isrs  # --isr NAME@HZ: (name, period_s)
            # --mcu-time: 1 measured (the program reports its CPU time), 2 fixed, 0 off
            mcu_mode = 0.0 if mcu is None else 1.0 if measured else 2.0
            self._reply(struct.pack("<7d", h, w, s.line_row, 1.0 if s.recording else 0.0,
                                    s.wheelbase_m, mcu_mode, len(isrs))
                        + struct.pack("<4d", *_sensor_spec(s._s.car))
                        + b"".join(struct.pack("<2d", period, len(name.encode())) + name.encode()
                                   for name, period in isrs))
            self._serve()
        except RunFinished as exc:
            if isinstance(exc, Stalled):
                raise self._stalled(exc) from None
            self._reply(_HDR.pack(ST_FINISHED, 0))  # the child exits (stdio flushed)
            self._drain()
            raise
        except _ChildGone:
            self._ended()
        finally:
            self._close()

    def _interrupt(self, slot: int) -> None:
        """Run the program's interrupt handler ``slot`` now (the clock is inside a waiting call
        of the program): answer that call with ST_ISR (the slot, and the time: the handler's
        spinner_now without a round trip), then the handler's requests until it is done
        (OP_ISR_DONE); the waiting call then waits on for its own reply. Due in a queued
        request (--mcu-time charges those too), it runs inside the waiting call that came with
        it: the requests up to that call are read first and kept for after the handler."""
        if not self._in_call:
            self._read_to_call()
        outer = self._buf, self._pos, self._in_call
        self._buf, self._pos = b"", 0
        self._reply(_HDR.pack(ST_ISR, 12) + struct.pack("<id", slot, self.spinner._clock.time_s))
        self._serve(until_isr_done=True)
        self._buf, self._pos, self._in_call = outer

    def _read_to_call(self) -> None:
        """Read the unread requests up to the waiting one the program sent them with."""
        off = 0
        while True:
            if len(self._buf) - self._pos < off + 8:
                self._fill(off + 8)
            op, n = _HDR.unpack_from(self._buf, self._pos + off)
            off += 8 + n
            if len(self._buf) - self._pos < off:
                self._fill(off)
            if op in _WAITING:
                return

    def _serve(self, until_isr_done: bool = False) -> None:
        """Answer requests until the child ends (raises _ChildGone) or the run does (or, with
        ``until_isr_done``, until the interrupt handler running ends).

        A camera frame's usual requests - the queued command, then the image call - arrive
        in one read of exactly those bytes: they are answered from one unpack (the same
        calls in the same order as message by message), the reply and the next read in one
        :meth:`_exchange`. Not with --mcu-time: each request is charged in :meth:`_handle`."""
        s, recv, exchange, refused = self.spinner, self._recv, self._exchange, self._refused
        frame_size = _FRAME.size if self._mcu is None else -1
        unpack_frame = _FRAME.unpack
        while True:
            if self._pos == len(self._buf):  # all read: read anew
                buf = recv()
                while len(buf) == frame_size:
                    op, n, v, d, yaw, op2, n2, line, noise = unpack_frame(buf)
                    if op != OP_CMD or n != _CMD.size or op2 != OP_IMAGE or n2 != _2I.size:
                        break
                    self._in_call = True  # the image call came with the command
                    try:
                        self.yaw = yaw
                        s.set_speed_and_servo(v, d) if v == v else s.set_servo(d)
                    except _PASS:
                        raise
                    except Exception as exc:
                        refused(exc)
                    try:
                        img = s.get_image(line, noise != 0)
                    except _PASS:
                        raise
                    except Exception as exc:
                        refused(exc)
                        buf = recv()
                    else:
                        buf = exchange(img)
                self._buf, self._pos = bytes(buf), 0  # a copy if it was the host's buffer
            op, payload = self._message()
            if op == OP_ISR_DONE and until_isr_done:
                return
            self._in_call = op in _WAITING
            try:
                self._handle(op, payload)
            except _PASS:
                raise
            except Exception as exc:
                refused(exc)

    def _refused(self, exc: Exception) -> None:
        """A call the simulator refused: the child reports it (with where) on reading this."""
        text = str(exc).encode()
        self._reply(_HDR.pack(ST_ERROR, len(text)) + text)

    def _handle(self, op: int, payload: bytes) -> None:
        """Answer one request (replying to the waiting ones). With --mcu-time every request but
        the exempt ones (``_UNCHARGED``) is charged first, here where each passes: the program's
        time since its previous one passes before the request acts (simrunner.run.mcu); the
        Spinner methods answering it are calls inside it, not charged again."""
        mcu = self._mcu
        if mcu is None:
            self._answer(op, payload)
            return
        mcu.enter(charge=op not in _UNCHARGED)  # (an exempt one's Spinner calls are inside it: not charged)
        try:
            self._answer(op, payload)
        finally:
            mcu.leave()

    def _answer(self, op: int, payload: bytes) -> None:
        s, reply = self.spinner, self._reply
        if op == OP_CMD:  # speed NaN: a steering-only command (set_motors' duties are kept)
            v, d, self.yaw = _CMD.unpack(payload)
            s.set_speed_and_servo(v, d) if v == v else s.set_servo(d)
        elif op == OP_IMAGE:
            line, noise = _2I.unpack(payload)
            img = s.get_image(line, noise != 0)
            reply(_HDR.pack(ST_OK, img.size) + img.tobytes())
        elif op == OP_LATEST_IMAGE:  # {line, noise (int32), after (int64)} -> {frame (int64), image if newer}
            line, noise, after = struct.unpack("<iiq", payload[:16])
            frame, img = s.latest_image(line, noise != 0, after)
            data = b"" if img is None else img.tobytes()
            reply(_HDR.pack(ST_OK, 8 + len(data)) + struct.pack("<q", frame) + data)
        elif op == OP_TEXT:
            (count,) = struct.unpack_from("<i", payload)
            parts = payload[4:].split(b"\0")[:count]
            s.add_data([p.decode("utf-8", "replace") for p in parts])
        elif op == OP_TIME:
            reply(_HDR.pack(ST_OK, 8) + _D.pack(s.get_time()))
        elif op == OP_NOW or op == OP_NOW_UNCHARGED:  # spinner_now (charged), spinner_now_uncharged: the
            reply(_HDR.pack(ST_OK, 8) + _D.pack(s._clock.time_s))  # clock's time, no step
        elif op == OP_SPEED:
            reply(_HDR.pack(ST_OK, 8) + _D.pack(s.get_speed()))
        elif op == OP_POSITION:
            reply(_HDR.pack(ST_OK, 24) + _3D.pack(*s.get_position()))
        elif op == OP_SLEEP:
            s.sleep(_D.unpack(payload)[0])
            reply(_OK_EMPTY)
        elif op == OP_LINE:
            rows, width = _2I.unpack_from(payload)
            s.add_data(np.frombuffer(payload, np.uint8, rows * width, 8).reshape(rows, width))
        elif op == OP_NOISE:
            rows, width = _2I.unpack_from(payload)
            img = np.frombuffer(payload, np.uint8, rows * width, 8).reshape(rows, width).copy()
            out = np.ascontiguousarray(s.add_noise(img), dtype=np.uint8)
            reply(_HDR.pack(ST_OK, out.size) + out.tobytes())
        elif op == OP_PARAM:
            reply(_HDR.pack(ST_OK, 8) + _D.pack(self._param(payload)))
        elif op == OP_SET_EXPOSURE:
            s.set_exposure(_D.unpack(payload)[0])
            reply(_OK_EMPTY)
        elif op == OP_SET_EXPOSURE_NEXT:  # the exposure from the next frame on (a kit's period register)
            s.set_exposure(_D.unpack(payload)[0], next_frame=True)
            reply(_OK_EMPTY)
        elif op == OP_FREE_RUNNING:
            s.camera_free_running()
            reply(_OK_EMPTY)
        elif op == OP_GET_EXPOSURE:
            reply(_HDR.pack(ST_OK, 8) + _D.pack(s.get_exposure()))
        elif op == OP_DISTANCE:
            reply(_HDR.pack(ST_OK, 8) + _D.pack(s.get_distance(payload.decode("utf-8", "replace"))))
        elif op == OP_MOTORS:  # the rear motors' duties: two doubles
            s.set_motors(*struct.unpack("<2d", payload[:16]))
        elif op == OP_EVERY:  # a timer interrupt: its period (double) and the program's slot for it (int32)
            period, slot = struct.unpack("<di", payload[:12])
            self._isrs[slot] = handler = lambda: self._interrupt(slot)
            kept = self._latched.pop(slot, None)  # its slot's stop kept a call: one NVIC bit, on the new one
            pending = kept is not None and s._clock.unpend_interrupt(kept) > 0
            s.every(period, handler)
            if pending:
                s._clock.hold_pending(handler)
        elif op in (OP_EVERY_STOP, OP_EVERY_STOP_LATCHED):  # the program's slot (int32) of a timer interrupt
            slot = struct.unpack("<i", payload[:4])[0]  # it stopped; latched, byte 1 where a call due keeps
            handler = self._isrs.pop(slot, None)  # its pending bit
            if payload[4:5] == b"\x01":  # (a kit's timer whose interrupt enable was cleared: the NVIC's bit)
                self._latched[slot] = handler
                s._clock.remove_interrupt(handler, latch=True)
            else:
                s.stop_every(handler)
        elif op == OP_EVERY_UNPEND:  # the slot (int32) of a stopped one whose pending bit is cleared
            s._clock.unpend_interrupt(self._latched.pop(struct.unpack("<i", payload[:4])[0], None))
        elif op in (OP_PEND, OP_PEND_WAIT):  # the slot (int32) whose pending bit is set (NVIC_SetPendingIRQ)
            slot = struct.unpack("<i", payload[:4])[0]
            handler = self._isrs.get(slot) or self._latched.get(slot)
            if handler is None:  # (no timer: a handler of its own, kept as a stopped one's kept call)
                self._latched[slot] = handler = lambda: self._interrupt(slot)
            s._clock.pend_interrupt(handler)  # (unmasked: it runs now, in the waiting call)
            if op == OP_PEND_WAIT:
                reply(_OK_EMPTY)
        elif op == OP_EVERY_PENDING:  # a handler's slots (int32 each) -> int32 1 when a call of it fell due
            slots = struct.unpack_from(f"<{len(payload) // 4}i", payload)  # and has not run (NVIC_GetPendingIRQ;
            handlers = (self._isrs.get(slot) or self._latched.get(slot) for slot in slots)  # no time passes)
            pending = any(h is not None and s._clock.is_pending(h) for h in handlers)
            reply(_HDR.pack(ST_OK, 4) + struct.pack("<i", pending))
        elif op in (OP_IRQ_MASK, OP_IRQ_MASK_WAIT):  # a flag byte: 1 mask (disable), 0 unmask (enable)
            if payload[:1] == b"\x01":  # then the caller's return address: its offset (uint64), module
                clock, was = s._clock, s._clock.masked
                s.disable_interrupts()
                if not was:  # where the program masked (for the warning of interrupts left disabled)
                    clock.mask_where = self._mask_where(bytes(payload))
            else:
                s.enable_interrupts()  # (the pending handlers run here: ST_ISR in a waiting one)
            if op == OP_IRQ_MASK_WAIT:
                reply(_OK_EMPTY)
        elif op == OP_CPU:  # the program's CPU time since its previous request (--mcu-time measured)
            s._s.mcu.report(_D.unpack(payload)[0])
        elif op == OP_ENCODER:  # the wheel's index (int32) -> its count (int64)
            reply(_HDR.pack(ST_OK, 8) + struct.pack("<q", s.get_encoder(struct.unpack("<i", payload[:4])[0])))
        elif op == OP_IMU:  # a flag byte (0: the gyroscope, 1: the accelerometer) -> 3 doubles
            reply(_HDR.pack(ST_OK, 24) + _3D.pack(*(s.get_accel() if payload[:1] == b"\x01" else s.get_gyro())))
        elif op == OP_SCAN:  # a flag byte (0: the readings, 1: the rays' angles), the name
            name = payload[1:].decode("utf-8", "replace")
            values = np.ascontiguousarray(s.scan_angles(name) if payload[:1] == b"\x01" else s.get_scan(name),
                                          dtype="<f8")
            reply(_HDR.pack(ST_OK, values.nbytes) + values.tobytes())
        elif op in (OP_PIXY_FEATURES, OP_PIXY_SET, OP_PIXY_PROG):
            if self._pixy is None:
                self._pixy = s.pixy2()
            reply(_pixy2_answer(self._pixy, op, payload))
        elif op == OP_WARN:  # spinner_warn's text, NUL, its frames: a warning of the run, once per text
            raw, _, frames = payload.partition(b"\0")
            text = raw.decode("utf-8", "replace")
            if not s._s.has_warned("spinner_warn: " + text):
                where = self._warned_at(frames.decode("utf-8", "replace"))
                s._s.warn_once("spinner_warn: " + text, f"{where}: {text}" if where else text)
        elif op == OP_FAULT:
            self._fault(payload.decode("utf-8", "replace"))
        elif op == OP_EXIT_AT:  # the exit call (uint8), its status (int32), its return address' offset
            fn, status, offset = struct.unpack_from("<BiQ", payload)  # (uint64) and module: just before
            where = self._where(payload[13:].decode("utf-8", "replace"), offset)  # the program ends
            at_load, fn = fn & EXIT_AT_LOAD, fn & ~EXIT_AT_LOAD  # (in a constructor, as the library loaded)
            name = ("exit", "_exit", "_Exit", "quick_exit")[fn] if fn < 4 else "exit"
            self._exit_at = (f"{name}({status}) at {where}" + (f", {IN_CONSTRUCTOR}" if at_load else "")
                             if where else None)
            self._exit_status = status & 0xFF
        else:
            raise ControllerError(f"{self.name}: unknown request {op} from the host program")

    def _mask_where(self, payload: bytes) -> Callable[[], str | None] | None:
        """The ``where`` of a mask message (its return address' offset and module), the same
        function for the same place."""
        if payload != self._last_mask[0]:
            offset = struct.unpack_from("<Q", payload, 1)[0] if len(payload) >= 9 else 0
            module = payload[9:].decode("utf-8", "replace")
            self._last_mask = (payload, (lambda: self._where(module, offset)) if module else None)
        return self._last_mask[1]

    def _where(self, module: str, offset: int) -> str | None:
        """file:line of the return address at ``offset`` in ``module`` when it is the program's
        own code (not the kits'); in the program's library without debug information (a prebuilt
        one), what its symbol table says: ``libx.so+0x1153 (in tick(); no debug information in
        libx.so: build it with -g for its file:line)``; else None."""
        from simrunner.run.native.symbolize import _addr2line, _ours, no_line_where

        found = _addr2line(module, [offset - 1]).get(offset - 1)  # (a return address: after its call)
        frame = next((f for f in found or () if f[1] and not _ours(f[1])), None)
        if frame is not None:
            return f"{frame[1]}:{frame[2]}"
        if found is None or any(f[1] for f in found):  # (no addr2line; or in a kit's code, the simulator's)
            return None
        if os.path.realpath(module) not in {os.path.realpath(m) for m in self._user_modules()}:
            return None
        return no_line_where(module, offset - 1, found[0][0] if found else "")

    def _warned_at(self, frames: str) -> str | None:
        """file:line of the innermost frame of a warning's ``frames`` (the host's report lines) in
        the program's own code, not a kit's (None: none there, or no debug information)."""
        if not frames:
            return None
        from simrunner.run.native.symbolize import _ours, parse_report

        fault = parse_report("signal 0\n" + frames, self._user_modules(), self._host())
        loc = fault.location
        return f"{loc.file}:{loc.line}" if loc is not None and not _ours(loc.file) else None

    def _param(self, payload: bytes) -> float:
        default = _D.unpack_from(payload)[0]
        name = payload[8:].decode("utf-8", "replace")
        value = self.spinner.param(name, default)  # --param (simrunner.run.params)
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"spinner_param({name!r}): value {value!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"spinner_param({name!r}): value {value!r} is not finite")
        return v

    # -- endings ---------------------------------------------------------------------
    def _host(self) -> str:
        """Path of the module that hosts the program (its frames are not the program's)."""
        return str(self.ctrl.host)

    def _user_modules(self) -> set[str]:
        return {str(self.ctrl.program.library)}

    def _fault(self, report: str) -> None:
        """The child reported a fault: wait for it to end, raise ControllerError."""
        from simrunner.run.native.symbolize import fault_message, format_traceback, parse_report

        fault = parse_report(report, self._user_modules(), self._host())
        if not fault.signal:  # a kit that looked for a function may have met a misspelt one
            fault = dataclasses.replace(fault, message=misspelt_function(self.ctrl.program, fault.message))
        self._drain()
        raise ControllerError(fault_message(fault), format_traceback(fault, self.name))

    def _stalled(self, exc: Stalled) -> Stalled:
        """Ask the stalled child where it is (SIGUSR1), then end it; the message names the line."""
        where = ""
        try:
            self._ask_where()
            deadline = time.monotonic() + 5.0  # a loaded machine can be slow to answer
            while True:
                op, payload = self._message(deadline)
                if op == OP_FAULT:
                    from simrunner.run.native.symbolize import parse_report

                    fault = parse_report(payload.decode("utf-8", "replace"),
                                                self._user_modules(), self._host())
                    loc = fault.location
                    if loc is not None:
                        where = f" (at {loc.file}:{loc.line} in {loc.function})"
                    break
        except (_ChildGone, OSError):
            pass
        self._kill()
        message = native_stall_hint(exc.message, getattr(self.ctrl.program, "kit", None))  # its calls
        if where:
            head, sep, tail = message.partition("; ")
            message = f"{head}{where}{sep}{tail}"
        clock = self.spinner._clock  # the run's clock records how it ended (simrunner.run)
        clock.finished = Stalled(message)
        return Stalled(message)

    def _ask_where(self) -> None:
        """Make the stalled program report where it is (a FAULT report)."""
        self.proc.send_signal(signal.SIGUSR1)

    def _ended(self) -> None:
        """The pipe closed without a fault report: the program returned or exited."""
        rc = self._wait()
        self._raise_exit(rc)

    def _raise_exit(self, rc: int) -> None:
        """Nothing for status 0; else the error that ends the run."""
        prog = self.ctrl.program
        lib = ", ".join(map(str, prog.sources)) if prog.sources else str(prog.library)
        # the call named is the one the status came from (not a later end: a signal, an exit
        # that no note names), and an exit(72) of the program's own is no missing main()
        exit_at = self._exit_at if self._exit_at and rc == self._exit_status else None
        if rc == 0:
            if exit_at:  # exit(0): the run ends as a return does, saying where
                raise RunFinished("controller_returned", f"the controller called {exit_at}")
            return
        if exit_at:  # (its file:line, as a Python controller's sys.exit is told)
            msg = f"the controller called {exit_at}"
            raise ControllerError(msg, msg + "\n")
        if rc == EXIT_NO_MAIN:
            raise ControllerFileError(f"{lib}: no main() function defined")
        if rc == EXIT_NOT_LOADED:
            err = self.child.load_error()
            raise ControllerFileError(missing_function(prog, err) or f"{lib}: cannot be loaded ({err})")
        if rc < 0:
            name = signal.Signals(-rc).name if -rc in signal.valid_signals() else str(-rc)
            msg = f"{self.name}: the controller was killed by {name}"
        else:
            msg = f"{self.name}: the controller exited with status {rc}"
        raise ControllerError(msg, msg + "\n")

    def _drain(self) -> None:
        """Read (and drop) what the child still sends until it exits (bounded), then reap it."""
        deadline = time.monotonic() + EXIT_WAIT_S
        try:
            while True:
                self._message(deadline)
        except (_ChildGone, OSError):
            pass
        self._wait()

    def _wait(self) -> int:
        try:
            return self.proc.wait(timeout=EXIT_WAIT_S)
        except subprocess.TimeoutExpired:
            self._kill()
            return self.proc.returncode

    def _kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()

    def _close(self) -> None:
        self.child.close()


_3I = struct.Struct("<3i")
_I = struct.Struct("<i")
_PIXY_SETTERS = {1: "set_mode", 2: "set_next_turn", 3: "set_default_turn", 4: "set_vector",
                 5: "reverse_vector", 6: "set_camera_brightness", 7: "init", 8: "set_lamp", 9: "get_resolution"}


def _pixy2_answer(pixy, op: int, payload: bytes) -> bytes:
    """The reply to a Pixy2 request of pixy2_line.h (``spinner_host.c``'s pixy_* functions), from
    ``pixy`` (a :class:`simrunner.run.pixy2.Pixy2`)."""
    from simrunner.run.pixy2 import pack_features

    if op == OP_PIXY_PROG:
        result = pixy.change_prog(payload.decode("utf-8", "replace"))
    elif op == OP_PIXY_SET:
        what, value = _2I.unpack(payload)
        name = _PIXY_SETTERS.get(what)
        if name is None:
            raise ControllerError(f"unknown Pixy2 request {what} from the host program")
        if name in ("reverse_vector", "init", "get_resolution"):
            result = getattr(pixy.line if name == "reverse_vector" else pixy, name)()
        elif name == "set_lamp":
            result = pixy.set_lamp(value >> 8, value & 0xFF)
        elif name == "set_camera_brightness":
            result = pixy.set_camera_brightness(value)
        else:
            result = getattr(pixy.line, name)(value)
    else:
        main, features, wait = _3I.unpack(payload)
        line = pixy.line
        result = (line.get_main_features if main else line.get_all_features)(features, wait != 0)
        data = _I.pack(result) + (b"" if result < 0 else pack_features(line))
        return _HDR.pack(ST_OK, len(data)) + data
    return _HDR.pack(ST_OK, 4) + _I.pack(result)
