"""Controller faults that would lose a run, turned into outcomes (docs/drive.md, "When a
controller misbehaves").

- ``sys.exit(n)`` / ``raise SystemExit`` in a controller (``main`` or the module's top level)
  ends the run like ``main`` returning (status 0 or None) or failing (any other status):
  :func:`exit_outcome`. ``os._exit(n)`` called in the run's thread does the same
  (:class:`ControllerGuards` replaces it while the run executes); the outputs are written.
- ``time.sleep(s)`` called by the controller's code in the run's thread waits ``s`` of
  *simulated* time, like ``spinner.sleep`` and ``usleep`` in C controllers
  (:class:`ControllerGuards`); in every other thread, and where the simulator's own code
  sleeps in the run's thread (directly or through a library, e.g. ``subprocess``'s bounded
  waits in the C bridge), it is the real sleep.
- SIGTERM and SIGHUP end the run like Ctrl-C (:class:`SignalGuard`): the outputs are written
  and the exit code is 128 + the signal's number (143, 129; Ctrl-C: 130).
- Threads the controller started and left running are reported (:func:`stray_threads`); the
  CLI does not wait for them.
- A process the controller forks (``os.fork``, multiprocessing's fork) is not the run's: its
  Spinner calls end it with a message (exit status 70) and where its ``main`` ends, it ends
  (:func:`end_forked_child`), so the run's log and outputs are the parent's alone.

The patches are installed only while at least one run executes (a reference count, so runs
in several threads nest) and are removed afterwards.
"""
from __future__ import annotations

import math
import os
import signal
import sys
import sysconfig
import threading
import time
from pathlib import Path

from simrunner.errors import ControllerError
from simrunner.run.controller import PACKAGE_DIR, user_traceback
from simrunner.run.result import Outcome

_real_sleep = time.sleep
_real_exit = os._exit
# code that sleeps on behalf of its caller: the standard library and installed packages
_LIBRARY_DIRS = tuple(sorted({sysconfig.get_paths()[k] for k in ("stdlib", "platstdlib", "purelib",
                                                                 "platlib")}))
_PACKAGE_PREFIX = os.path.join(PACKAGE_DIR, "")
_SIGNALS = tuple(s for s in (getattr(signal, "SIGTERM", None), getattr(signal, "SIGHUP", None))
                 if s is not None)


class ControllerExit(SystemExit):
    """``os._exit(status)`` called by the controller, turned into ``SystemExit``."""

    def __init__(self, status: int):
        super().__init__(status)
        self.how = "os._exit"


class Terminated(KeyboardInterrupt):
    """SIGTERM / SIGHUP received while a run executes (a ``KeyboardInterrupt``, so the
    controller's ``except Exception`` does not swallow it)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)


# -- where in the user's code ---------------------------------------------------------------
def _is_user_file(filename: str) -> bool:
    return not (filename.startswith(PACKAGE_DIR) or filename.startswith("<")
                or filename == __file__ or "/threading.py" in filename)


def caller_location(depth: int = 1) -> str:
    """``file:line`` of the innermost frame of the caller's stack that is not the
    simulator's (the user's line), or ``""``."""
    f = sys._getframe(depth)
    while f is not None:
        if _is_user_file(f.f_code.co_filename):
            return f"{Path(f.f_code.co_filename).name}:{f.f_lineno}"
        f = f.f_back
    return ""


def _traceback_location(exc: BaseException) -> str:
    tb, where = exc.__traceback__, ""
    while tb is not None:
        name = tb.tb_frame.f_code.co_filename
        if _is_user_file(name):
            where = f"{Path(name).name}:{tb.tb_lineno}"
        tb = tb.tb_next
    return where


def exit_outcome(exc: SystemExit) -> tuple[Outcome, str, ControllerError | None]:
    """``(outcome, message, error)`` of a controller that called ``sys.exit`` / ``os._exit``:
    status 0 or None is ``controller_returned``, anything else ``controller_error``."""
    how = getattr(exc, "how", "sys.exit")
    code = exc.code
    where = _traceback_location(exc)
    at = f" at {where}" if where else ""
    if code is None or code == 0:
        return Outcome.CONTROLLER_RETURNED, f"the controller called {how}({code!r}){at}", None
    message = f"the controller called {how}({code!r}){at}"
    tb = user_traceback(exc).rstrip()
    return Outcome.CONTROLLER_ERROR, message, ControllerError(message, f"{tb}\n{message}\n")


# -- time.sleep and os._exit while a run executes -------------------------------------------
class _Patches:
    """Install of the sleep and exit replacements while any run executes (runs in threads
    nest); ``sessions``: the sessions of the runs executing now (for :func:`orphan_call`)."""

    lock = threading.Lock()
    sessions: list = []
    forked = False  # this process is one a running controller forked (_after_fork_in_child)

    @classmethod
    def acquire(cls, session) -> None:
        with cls.lock:
            cls.sessions.append(session)
            if len(cls.sessions) == 1:
                time.sleep = _sleep
                os._exit = _exit

    @classmethod
    def release(cls, session) -> None:
        with cls.lock:
            cls.sessions.remove(session)
            if not cls.sessions:
                time.sleep = _real_sleep
                os._exit = _real_exit


def orphan_call(method: str) -> str | None:
    """For ``Spinner()`` built in a thread without a run: if runs execute in this process
    (so it is a thread a controller started), end them with ``controller_error`` and return
    the message; else None."""
    with _Patches.lock:
        sessions = list(_Patches.sessions)
    if not sessions:
        return None
    message = foreign_thread_message(method)
    for session in sessions:
        session.clock.finish("controller_error", message)
    return message


def _run_session():
    """The session of the run executing in this thread, or None."""
    from simrunner.run.context import current_session

    session = current_session()
    if session is None or session.thread_id != threading.get_ident():
        return None
    return session


def _called_by_simulator(frame) -> bool:
    """True when the innermost frame from ``frame`` outwards that is not library code (the
    standard library, installed packages) is the simulator's own: it sleeps, not the
    controller."""
    f = frame
    while f is not None:
        name = f.f_code.co_filename
        if name.startswith(_PACKAGE_PREFIX):
            return True
        if not (name.startswith(_LIBRARY_DIRS) or name.startswith("<frozen ")):
            return False  # the controller's code (its file, its helpers, a test's callable)
        f = f.f_back
    return False


def _sleep(seconds) -> None:
    session = _run_session()
    if session is None or _called_by_simulator(sys._getframe(1)):
        return _real_sleep(seconds)
    s = float(seconds)  # TypeError for non-numbers, as time.sleep
    if s < 0 or math.isnan(s):
        raise ValueError("sleep length must be non-negative")
    clock = session.clock
    clock.advance(max(1, math.ceil(s / clock.dt_s - 1e-9)) if math.isfinite(s) else 1 << 62)


def _exit(status: int) -> None:
    if _run_session() is None:
        _real_exit(status)
    raise ControllerExit(status)


def _after_fork_in_child() -> None:
    """A fork from the thread of an executing run (os.register_at_fork): mark this process as
    the controller's child (module docstring); no run executes in it."""
    if _run_session() is None:
        return
    time.sleep, os._exit = _real_sleep, _real_exit  # (the Spinner's own hook ends its calls)
    _Patches.lock, _Patches.sessions, _Patches.forked = threading.Lock(), [], True


os.register_at_fork(after_in_child=_after_fork_in_child)


def end_forked_child() -> None:
    """Where the ``main`` of a process the controller forked ends (returns, raises, exits):
    the process ends there (status 0, the SystemExit's, else 1), writing nothing of the run."""
    if not _Patches.forked:
        return
    exc = sys.exc_info()[1]
    code = 0 if exc is None else exc.code if isinstance(exc, SystemExit) and isinstance(exc.code, int) else 1
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    _real_exit(code)


class ControllerGuards:
    """Context manager around a run's execution: installs the ``time.sleep`` / ``os._exit``
    replacements (see the module docstring)."""

    def __init__(self, session) -> None:
        self.session = session

    def __enter__(self) -> "ControllerGuards":
        _Patches.acquire(self.session)
        return self

    def __exit__(self, *exc) -> None:
        _Patches.release(self.session)


# -- signals ------------------------------------------------------------------------------
class SignalGuard:
    """SIGTERM and SIGHUP end the run like Ctrl-C (main thread only; elsewhere a no-op).

    While ``clock`` is set (the run executes): a signal that arrives in the user's code raises
    :class:`Terminated` there; one that arrives in the simulator's code ends the run at the
    next Spinner call (``clock.finish("interrupted")``), so no part is left half-updated.
    Without a clock (loading): raises :class:`Terminated`. After ``writing = True`` (the
    outputs are being written) the signal is only noted. A second signal gets the default
    action (the process ends). ``received`` is the first signal's number (or None).
    """

    def __init__(self) -> None:
        self.received: int | None = None
        self.clock = None
        self.writing = False
        self._old: dict = {}
        self.enabled = threading.current_thread() is threading.main_thread()

    def _handler(self, signum, frame) -> None:
        if self.received is not None:  # a second signal: the default action
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        self.received = signum
        if self.writing:
            return
        name = signal.Signals(signum).name
        if self.clock is not None and frame is not None and not _is_user_file(frame.f_code.co_filename):
            self.clock.finish("interrupted", f"{name} received")
            return
        raise Terminated(signum)

    def __enter__(self) -> "SignalGuard":
        if self.enabled:
            for s in _SIGNALS:
                self._old[s] = signal.signal(s, self._handler)
        return self

    def __exit__(self, *exc) -> None:
        for s, old in self._old.items():
            signal.signal(s, old)
        self._old = {}


def exit_code(outcome: str, signum: int | None) -> int:
    """The CLI's exit code: 0 success, 1 the run failed, 128 + N after signal N (Ctrl-C:
    130)."""
    if Outcome(outcome).ok:
        return 0
    if outcome == Outcome.INTERRUPTED:
        return 128 + (signum or signal.SIGINT)
    return 1


# -- threads ------------------------------------------------------------------------------
def stray_threads(before: set[threading.Thread]) -> list[str]:
    """Descriptions of the non-daemon threads started since ``before`` that still run."""
    out = []
    for t in threading.enumerate():
        if t in before or t.daemon or not t.is_alive():
            continue
        target = getattr(t, "_target", None)
        code = getattr(target, "__code__", None) or getattr(type(t).run, "__code__", None)
        where = f" ({Path(code.co_filename).name}:{code.co_firstlineno})" if code is not None else ""
        out.append(f"thread {t.name!r}{where}")
    return out


def foreign_thread_message(method: str) -> str:
    """The message for a Spinner call from a thread that does not run ``main``."""
    where = caller_location(3)
    at = f" at {where}" if where else ""
    return (f"Spinner.{method}() called from thread {threading.current_thread().name!r}{at}: only "
            f"the thread running main() may use the Spinner")


__all__ = ["ControllerExit", "ControllerGuards", "SignalGuard", "Terminated", "caller_location",
           "exit_code", "exit_outcome", "foreign_thread_message", "orphan_call", "stray_threads"]
