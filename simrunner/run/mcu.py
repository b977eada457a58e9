"""The microcontroller's time (``--mcu-time``): the controller's own processing costs simulated
time, as on the car, where a frame's processing delays the command that follows it.

Without it (the default) simulated time passes only inside the Spinner's calls that wait or
read a sensor, so a controller's code runs in no time at all. With it, the time the controller
spent since its previous call passes, with the commands in force until then, so a slow
algorithm's commands come late and it may miss camera frames:

- ``measured``: the CPU time the controller used between the two calls (its thread's CPU
  clock for a Python controller; a C/C++ program reports its own thread's CPU clock with each
  request), times ``scale``, how many times slower the target MCU runs the code than this
  machine (docs/drive.md lists estimates per kit: measure yours). Not deterministic: the same
  run on another machine, or under load, charges other times.
- a fixed number of seconds per call: deterministic.

The charge is whole physics steps (``dt``); the rest is carried to the next call, so no time is
lost.

Where the time passes (the rule; docs/drive.md). **Every request of the program's code to the
simulator is charged**: before the simulator acts on it or answers it, the program's time since
its previous charged request passes - whether the call lets time pass itself (a sensor read, a
wait) or not (a command, a setting, a timer's start or stop, a query such as ``get_exposure``,
``scan_angles``, a Pixy2 call). On the MCU that time has passed by then too: a timer that fell
due in it interrupts before the call, and the call acts after it; and a program that computes
and then makes only calls that let no time pass takes time for its work. With a fixed cost each
request costs it. The requests:

- Python: each call of a public method of the Spinner, of its Pixy2 (``spinner.pixy2()``) and of
  the Pixy2's ``line``, their camelCase aliases too (:func:`api_calls` lists them,
  :func:`charge_calls` charges each) but :data:`UNCHARGED_METHODS`. Attributes and properties
  (``line_row``, ``image_shape``, ``recording``, ``pixy.frame_width``, ``pixy.line.vectors``)
  are what the program holds, no calls.
- C/C++: each message a call of spinner.h or pixy2_line.h sends (spinner.hpp's and Pixy2.h's
  members, the kits' libraries - TFC_*, mbed's, the S32K144 RTD's - and usleep, sleep,
  nanosleep, clock_nanosleep make theirs through those: a kit's function costs one charge per
  request it sends), charged where the simulator takes every request
  (:meth:`simrunner.run.native.bridge._Session._handle`) but :data:`UNCHARGED_REQUESTS`. A call
  with nothing to send is answered inside the program, as on the MCU by a read of a variable or
  a core register, and is not charged: :data:`UNCHARGED_C_FUNCTIONS`, and a call that changes
  nothing (a second ``spinner_disable_interrupts``, ``spinner_enable_interrupts`` unmasked,
  ``spinner_stop_every`` of a handler not set up). Python's same calls are charged: with a fixed
  cost one charge more; measured the same, as nothing depends on where the time before a call
  without an effect passes. The requests exempt are not calls of the program's code (its CPU
  time, a handler's end, its end), ``spinner_warn``, and the kits' bookkeeping - their NVIC
  emulation and ``spinner_now_uncharged``: sent at the kit's look at the registers the program
  wrote, or for the time a timer it starts counts from, they have no time of their own in the
  program's; the program's time passes at its next call.

A read of the time is a request like any other: ``spinner_now`` in ``main()``, and so the kits'
timer registers whose counts are made with it (the TFC kit's PIT, LPTMR0 and TPM2 counters while
they count, the S32K144 kit's Gpt reads, input pins and conversions), each a round trip with a
charge. On the MCU a loop that polls a clock spends its time reading it:
``while (spinner_now() < t0 + 0.005) {}`` ends 5 ms later (measured: by the CPU time its reads take; fixed: one cost a read), where without
the charge no time passed in it and the watchdog ended the run. Python has no such read:
``get_time`` is charged and lets a physics step pass.

Calls made inside another call (a Pixy2 call's exposure, the bridge's request answered by a
Spinner method) are charged once, and calls in an interrupt handler not at all: no simulated
time passes in a handler. Measured, a handler's own CPU time is charged, times ``scale``, at
main's next charged call, in both languages alike: a C handler reports it with its requests and
its end; a Python handler's is its thread's CPU clock around it, less the Spinner calls it makes
(:meth:`McuTime.run_handler`). With a fixed cost a handler costs nothing (its calls are not
charged), C and Python alike.
"""
from __future__ import annotations

import functools
import inspect
import math
import time

#: The Python calls not charged (the rule's exemptions), each with the reason: what the program
#: holds or does itself, as the C functions of the same name do.
UNCHARGED_METHODS = {
    "configure": "the program's own norm functions (C: spinner_configure stays in the program)",
    "default_diff_norm": "a formula of the program's own (v sin(delta) / L)",
    "interrupts_disabled": "reads PRIMASK, a core register the program reads in one instruction (C: "
                           "spinner_interrupts_disabled stays in the program; the kits read it at each "
                           "emulated register access)",
    "pixy2": "makes the library's object (C++: `Pixy2 pixy;`); its calls (init, ...) are charged",
}

#: The C functions (spinner.h, pixy2_line.h) not charged, each with the reason: most send no
#: request (answered inside the program from what it was given at its start or keeps itself);
#: spinner_now_uncharged, spinner_warn, spinner_fail and the kits' NVIC functions send one of
#: :data:`UNCHARGED_REQUESTS`.
UNCHARGED_C_FUNCTIONS = {
    "spinner_configure": "the program's own norm functions",
    "spinner_image_width": "the car's camera, given at the start",
    "spinner_image_height": "the car's camera, given at the start",
    "spinner_line_row": "the car's camera, given at the start",
    "spinner_recording": "given at the start",
    "spinner_encoder_lines": "the car's encoders, given at the start",
    "spinner_has_imu": "the car's IMU, given at the start",
    "spinner_has_every": "the program's own handler table",
    "spinner_interrupts": "the program's own handler table",
    "spinner_in_interrupt": "the program's own state (a handler runs)",
    "spinner_running": "the program's own state (a constructor at the load)",
    "spinner_interrupts_disabled": UNCHARGED_METHODS["interrupts_disabled"],
    "spinner_now_uncharged": "its request (OP_NOW_UNCHARGED) is exempt: see UNCHARGED_REQUESTS",
    "spinner_warn": "its request (OP_WARN) is exempt: see UNCHARGED_REQUESTS",
    "spinner_warn_at": "its request (OP_WARN) is exempt: see UNCHARGED_REQUESTS",
    "spinner_fail": "its request (OP_FAULT) ends the run",
    "spinner_stop_every_latched": "the kits' NVIC emulation (OP_EVERY_STOP_LATCHED): see UNCHARGED_REQUESTS",
    "spinner_unpend_every": "the kits' NVIC emulation (OP_EVERY_UNPEND): see UNCHARGED_REQUESTS",
    "spinner_pend_every": "the kits' NVIC emulation (OP_PEND, OP_PEND_WAIT): see UNCHARGED_REQUESTS",
    "spinner_every_pending": "the kits' NVIC emulation (OP_EVERY_PENDING): see UNCHARGED_REQUESTS",
}

_NVIC = ("the kits' NVIC emulation (spinner.h: for kits that emulate a timer's interrupt enable behind the "
         "NVIC): a kit sends it as it applies the register writes the program made since its previous call "
         "(its look), which have no time of their own in the program's. Charged there, the program's time "
         "passed between two writes the kit applies together: a PIT stopped by PIT_TCTRL0 = 0 before "
         "NVIC_EnableIRQ expired inside the enable, its IRQ on, and called its handler, which the board does "
         "not. The program's time passes at its next call")

#: The requests (simrunner.run.native.bridge's OP_ names) not charged, each with the reason.
UNCHARGED_REQUESTS = {
    "OP_CPU": "no call: the program's CPU time, sent before each request (measured)",
    "OP_ISR_DONE": "no call: a handler's end",
    "OP_FAULT": "no call: the program's fault (or spinner_fail), which ends the run",
    "OP_EXIT_AT": "no call: where the program called exit, as it ends",
    "OP_NOW_UNCHARGED": "spinner_now_uncharged: the time of the program's last charged call, for the kits' "
                        "bookkeeping of their registers (their look before a wait, the time a timer they start "
                        "counts from), which has no time of its own in the program's; charged there, a look "
                        "would let the time pass between two register writes it applies together (see the NVIC "
                        "requests). The program's reads of the time are spinner_now (OP_NOW), charged",
    "OP_WARN": "spinner_warn: a message to the person running the simulation, none on the car (the "
               "kits' register emulation warns)",
    "OP_EVERY_STOP_LATCHED": _NVIC,  # spinner_stop_every_latched
    "OP_EVERY_UNPEND": _NVIC,        # spinner_unpend_every (NVIC_ClearPendingIRQ)
    "OP_PEND": _NVIC,                # spinner_pend_every (NVIC_SetPendingIRQ; the kit's pending bits)
    "OP_PEND_WAIT": _NVIC,
    "OP_EVERY_PENDING": _NVIC,       # spinner_every_pending (NVIC_GetPendingIRQ)
}


def api_calls(cls: type) -> tuple[str, ...]:
    """The public calls of an API class (the Spinner, Pixy2, Pixy2Line): its methods and their
    aliases, not its properties, nor names starting with ``_``."""
    return tuple(name for name, value in vars(cls).items()
                 if not name.startswith("_") and inspect.isfunction(value))


def charge_calls(obj, mcu: "McuTime") -> None:
    """Charge ``mcu`` on each of ``obj``'s :func:`api_calls` but :data:`UNCHARGED_METHODS`."""
    for name in api_calls(type(obj)):
        if name not in UNCHARGED_METHODS:
            setattr(obj, name, timed(getattr(obj, name), mcu))


class McuTime:
    """The charge of one run (module docstring): ``fixed_s`` per call, or the measured CPU time
    times ``scale`` (``fixed_s`` None)."""

    def __init__(self, clock, *, fixed_s: float | None = None, scale: float = 1.0):
        self.clock = clock
        self.fixed_s = fixed_s
        self.scale = float(scale)
        self.reported = False   # a native program reports its CPU time (report)
        self.charged_s = 0.0    # simulated time charged so far (the summary's mcu_time_s)
        self._pending_s = 0.0   # CPU seconds not charged yet: reported, or a Python handler's
        self._debt_s = 0.0      # charged time not yet a whole physics step
        self._left_at: float | None = None  # thread CPU clock (s) as main's code resumed (Python)
        self._depth = 0
        self._handler_depth: int | None = None  # _depth as a Python handler began (None: none runs)
        self._handler_at = 0.0  # thread CPU clock (s) as the handler's own code resumed

    def report(self, cpu_s: float) -> None:
        """CPU seconds a native program spent since its previous request (its OP_CPU message)."""
        if math.isfinite(cpu_s) and cpu_s > 0.0:
            self._pending_s += cpu_s

    def enter(self, charge: bool = True) -> None:
        """A call begins: charged unless ``charge`` is False (an exempt request), it is inside
        another call, or in a handler (no time passes there; a Python handler's own time up to
        its call is kept for main's next charge)."""
        self._depth += 1
        if self._depth - 1 == self._handler_depth:  # a Python handler's call: its code's time so far
            self._pending_s += time.thread_time() - self._handler_at
        if not charge or self._depth > 1 or self.clock.in_interrupt:
            return
        if self.fixed_s is not None:
            spent = self.fixed_s
        elif self.reported:
            spent, self._pending_s = self._pending_s * self.scale, 0.0
        else:
            now = time.thread_time()
            own_s = 0.0 if self._left_at is None else now - self._left_at
            spent, self._pending_s = (own_s + self._pending_s) * self.scale, 0.0
        self.charged_s += spent
        self._debt_s += spent
        steps = math.floor(self._debt_s / self.clock.dt_s + 1e-9)
        if steps > 0:
            self._debt_s -= steps * self.clock.dt_s
            self.clock.advance(steps)

    def leave(self) -> None:
        self._depth -= 1
        if self._depth == self._handler_depth:  # back in a Python handler's own code
            self._handler_at = time.thread_time()
        elif self._depth == 0 and self.fixed_s is None and not self.reported and not self.clock.in_interrupt:
            self._left_at = time.thread_time()

    def run_handler(self, handler) -> None:
        """Run a timer interrupt's ``handler()`` (the clock's ``run_handler``). Measured, a Python
        program's handler's own CPU time - its thread's CPU clock around it, less the Spinner calls
        it makes - is kept and charged, times ``scale``, at main's next charged call, as a C
        handler's reported time is (no simulated time passes in a handler). With a fixed cost a
        handler costs nothing, in C neither: its calls are not charged."""
        if self.fixed_s is not None or self.reported or self._handler_depth is not None:
            handler()  # (a C handler reports its own time; handlers do not nest)
            return
        self._handler_depth, self._handler_at = self._depth, time.thread_time()
        try:
            handler()
        finally:
            self._pending_s += time.thread_time() - self._handler_at
            self._handler_depth = None


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
