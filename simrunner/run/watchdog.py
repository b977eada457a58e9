"""The wall-clock watchdog: stops a controller that never lets simulated time pass.

Two levels. A SIGALRM tick (every ``period_s``) raises :class:`Stalled` into a controller
that made no progress for ``limit_s``; that works while the interpreter runs Python code or
waits in an interruptible call. A controller stuck inside one C-level call that holds the
interpreter (``sum(range(10**12))``, a huge regex) never lets the tick run: for that every
tick re-arms ``faulthandler.dump_traceback_later(hard_limit_s, exit=True)``, a timer in a C
thread, so after ``hard_limit_s = limit_s + max(2, limit_s)`` without a tick the process
prints every thread's stack (the controller's file:line included, under ``Timeout
(h:mm:ss)!``) and exits with code 1. The run-log CSV then holds every row up to the stall
(it is written as the run goes). Under a supervisor (``simrunner drive``,
:mod:`simrunner.run.supervise`) the dump goes to the supervisor's report file instead, and
the supervisor writes the summary, plot and video from the run log; without one (``drive()``
in a process of its own) they are not written.
"""
from __future__ import annotations

import faulthandler
import signal
import sys
import threading
import time
from pathlib import Path

from simrunner.errors import Stalled
from simrunner.run.clock import LockstepClock
from simrunner.run.supervise import current_supervision


PYTHON_HINT = "call get_image(), sleep() or get_time() in every loop"
# A C/C++ program's hint names its calls that wait; a firmware built against a kit (--kit) lets
# time pass with its kit's calls (docs/firmware.md: an idle main loop whose work is the interrupts').
NATIVE_HINT = ("let simulated time pass in every loop: a call that waits (spinner_get_image(), spinner_sleep(0), "
               "spinner_get_time()) - a flag an interrupt sets is set only while time passes")
KIT_HINTS = {
    "tfc": "call TFC_Task() in every loop, or __WFI() in a main loop whose work is the interrupts' "
           "(for (;;) __WFI();)",
    "tfc-mbed": "call wait(), wait_ms() or sleep() in every loop, or read the board there (a main loop "
                "whose work is the Tickers': while (1) wait(1);)",
    "s32k144": ("let simulated time pass in every loop: a call that waits (LinearCameraGetFrame(), OsIf_TimeDelay(), "
                "OsIf_GetMilliseconds(); Spinner's spinner_sleep(0)) - a flag a Gpt notification sets is set only "
                "while time passes"),
}


def native_stall_hint(message: str, kit: str | None) -> str:
    """``message`` (:func:`stall_message`'s) with the hint in a C/C++ program's calls: those of
    ``kit`` (the program's --kit) where it has its own, else Spinner's C names."""
    return message.replace(PYTHON_HINT, KIT_HINTS.get(kit or "", NATIVE_HINT))


def stall_message(idle_s: float, where: str, limit_s: float, in_interrupt: bool = False) -> str:
    """The message of a stalled run (``where``: "" or " (at file:line in function)";
    ``in_interrupt``: it stalled inside an interrupt handler, where no time passes)."""
    hint = ("inside an interrupt handler no simulated time passes: a loop there that waits for "
            "time, the camera or the main loop never ends; wait in the main loop" if in_interrupt
            else PYTHON_HINT)
    return (f"controller stalled: {idle_s:.1f} s of wall time without letting simulated time "
            f"pass{where}; {hint} (limit --wall-limit {limit_s:g} s)")


class Watchdog:
    """SIGALRM every ``period`` s: if ``clock`` made no progress for ``limit_s`` of wall
    time, end the run and raise :class:`Stalled` in the controller. Works in the main
    thread (where signals are delivered); elsewhere it is disabled (``enabled`` False). The
    previous SIGALRM handler and timer are restored on exit."""

    def __init__(self, clock: LockstepClock, limit_s: float, user_file: str | None):
        self.clock = clock
        self.limit_s = float(limit_s)
        self.user_file = user_file
        self.period_s = min(0.25, self.limit_s / 4.0)
        self.armed = False
        self._old = None
        self.enabled = threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer")
        self.hard_limit_s = self.limit_s + max(2.0, self.limit_s)
        self._hard = False
        supervision = current_supervision()
        self._report = sys.__stderr__ if supervision is None else supervision.report

    def _where(self, frame) -> str:
        f = frame
        while f is not None:
            if self.user_file and f.f_code.co_filename == self.user_file:
                return f" (at {Path(f.f_code.co_filename).name}:{f.f_lineno} in {f.f_code.co_name})"
            f = f.f_back
        return ""

    def _arm_hard(self) -> None:
        """(Re)start the C-level timer of a stuck call (see the module docstring)."""
        try:
            faulthandler.dump_traceback_later(self.hard_limit_s, exit=True, file=self._report)
            self._hard = True
        except (AttributeError, ValueError, OSError, RuntimeError):  # no usable stderr
            self._hard = False

    def _handler(self, signum, frame) -> None:
        if not self.armed:
            return
        if self._hard:
            self._arm_hard()
        idle = time.monotonic() - self.clock.last_progress_wall_s
        if idle <= self.limit_s:
            return
        msg = stall_message(idle, self._where(frame), self.limit_s, self.clock.in_interrupt)
        self.clock.finish("stalled", msg)
        self.clock.last_progress_wall_s = time.monotonic()  # raise again only after another limit
        raise Stalled(msg)

    def __enter__(self) -> "Watchdog":
        if self.enabled:
            self._old = signal.signal(signal.SIGALRM, self._handler)
            signal.setitimer(signal.ITIMER_REAL, self.period_s, self.period_s)
            self._arm_hard()
        self.clock.stall_limit_s = self.limit_s  # for code outside the interpreter (C, inproc)
        self.armed = True
        return self

    def disarm(self) -> None:
        self.armed = False
        if self._hard:
            faulthandler.cancel_dump_traceback_later()
            self._hard = False
        if self.enabled and self._old is not None:
            signal.setitimer(signal.ITIMER_REAL, 0.0, 0.0)
            signal.signal(signal.SIGALRM, self._old)
            self._old = None

    def __exit__(self, *exc) -> None:
        self.disarm()
