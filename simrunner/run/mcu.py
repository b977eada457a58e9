"""The microcontroller's time (``--mcu-time``): the controller's own processing costs simulated
time, as on the car, where a frame's processing delays the command that follows it.

Without it (the default) simulated time passes only inside the Spinner's calls that wait or
read a sensor, so a controller's code runs in no time at all. With it, each call into the
Spinner API first lets the time the controller spent since its previous call pass, with the
commands in force until then (so a slow algorithm's commands come late, and it may miss camera
frames):

- ``measured``: the CPU time the controller used between the two calls (its thread's CPU
  clock for a Python controller; a C/C++ program reports its own thread's CPU clock with each
  request), times ``scale``, how many times slower the target MCU runs the code than this
  machine (docs/drive.md lists estimates per kit: measure yours). Not deterministic: the same
  run on another machine, or under load, charges other times.
- a fixed number of seconds per call: deterministic.

The charge is whole physics steps (``dt``); the rest is carried to the next call, so no time is
lost. Calls made from inside another call (the Spinner's own) are not charged twice, calls in
an interrupt handler not at all: no simulated time passes in a handler.
"""
from __future__ import annotations

import functools
import math
import time

#: The Spinner methods a controller calls (each charged on entry, the clock restarted on exit; their
#: camelCase aliases, the thesis's names, too).
TIMED_METHODS = ("set_servo", "set_speed", "set_speed_and_servo", "set_motors", "get_image", "get_speed", "get_position",
                 "get_distance", "get_scan", "get_encoder", "get_gyro", "get_accel", "get_time", "sleep",
                 "add_data", "add_noise", "set_exposure", "get_exposure", "camera_free_running", "param", "every",
                 "latest_image",
                 "disable_interrupts", "enable_interrupts")


class McuTime:
    """The charge of one run (module docstring): ``fixed_s`` per call, or the measured CPU time
    times ``scale`` (``fixed_s`` None)."""

    def __init__(self, clock, *, fixed_s: float | None = None, scale: float = 1.0):
        self.clock = clock
        self.fixed_s = fixed_s
        self.scale = float(scale)
        self.reported = False   # a native program reports its CPU time (report)
        self.charged_s = 0.0    # simulated time charged so far (the summary's mcu_time_s)
        self._pending_s = 0.0   # reported CPU seconds not charged yet
        self._debt_s = 0.0      # charged time not yet a whole physics step
        self._left_at: float | None = None
        self._depth = 0

    def report(self, cpu_s: float) -> None:
        """CPU seconds a native program spent since its previous request (its OP_CPU message)."""
        if math.isfinite(cpu_s) and cpu_s > 0.0:
            self._pending_s += cpu_s

    def enter(self) -> None:
        self._depth += 1
        if self._depth > 1 or self.clock.in_interrupt:  # (no time passes in a handler)
            return
        if self.fixed_s is not None:
            spent = self.fixed_s
        elif self.reported:
            spent, self._pending_s = self._pending_s * self.scale, 0.0
        else:
            now = time.thread_time()
            spent = 0.0 if self._left_at is None else (now - self._left_at) * self.scale
        self.charged_s += spent
        self._debt_s += spent
        steps = math.floor(self._debt_s / self.clock.dt_s + 1e-9)
        if steps > 0:
            self._debt_s -= steps * self.clock.dt_s
            self.clock.advance(steps)

    def leave(self) -> None:
        self._depth -= 1
        if self._depth == 0 and self.fixed_s is None and not self.reported and not self.clock.in_interrupt:
            self._left_at = time.thread_time()


def timed(method, mcu: McuTime):
    """``method`` (a bound Spinner method) charging ``mcu`` on entry and restarting it on exit."""
    @functools.wraps(method)
    def call(*args, **kwargs):
        mcu.enter()
        try:
            return method(*args, **kwargs)
        finally:
            mcu.leave()
    return call
