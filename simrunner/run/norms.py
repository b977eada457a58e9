"""A controller's norm functions, for reading a log written in the car's own command units.

A team that logs its commands as its code sends them (servo values, duty cycle in percent)
converts them to the run log's m/s and radians with the same functions its controller gives
the Spinner (``spinner.configure(speed_norm=..., turn_norm=...)``, :mod:`simrunner.run.spinner`).
:func:`controller_norms` takes them from the controller file itself: it runs ``main`` with a
stand-in for the Spinner that records what ``configure`` is given (each call, as the
Spinner does) and stops ``main`` at its next use of the Spinner; nothing is simulated. A column mapping then calls them row by row
(``speed_cmd_mps = "speed_norm(duty, servo)"``, :mod:`simrunner.telemetry.columns`).

Python controllers only: a C or C++ controller's norm functions are written as expressions
(docs/telemetry.md, "Logs with other columns or units").
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from simrunner.errors import ControllerFileError
from simrunner.run.controller import load_controller, user_traceback

NormFn = Callable[[float, float], float]


class _OsExit(SystemExit):
    """``os._exit`` in the probed controller (kept from ending the process)."""


class _TooLong(BaseException):
    """The probe's wall-time limit passed (raised by the alarm in the main thread)."""


class _Configured(BaseException):
    """Stops ``main`` at its first use of the Spinner after configuring its norms (a
    BaseException: a controller's ``except Exception`` does not catch it)."""


class _Stand_in:  # noqa: N801 - the name says what it is
    """What ``main(spinner)`` gets: ``configure`` records the norms as the Spinner's does
    (a later call replaces only what it gives) and returns the stand-in; the first other use
    of the Spinner stops ``main`` once norms are configured, and is an error naming the
    attribute before."""

    def __init__(self, path: Path):
        self._path = path
        self.norms: dict[str, NormFn] | None = None

    def configure(self, speed_norm: NormFn | None = None, speed_denorm: NormFn | None = None,
                  turn_norm: NormFn | None = None, diff_norm: NormFn | None = None) -> "_Stand_in":
        norms = dict(self.norms or {"speed_norm": _identity_speed, "turn_norm": _identity_angle})
        for name, fn in (("speed_norm", speed_norm), ("turn_norm", turn_norm)):
            if fn is not None:
                if not callable(fn):
                    raise ControllerFileError(f"{self._path}: configure({name}={fn!r}): expected a function "
                                              "(speed, angle)")
                norms[name] = fn
        self.norms = norms
        return self

    def __getattr__(self, name: str):
        if self.norms is not None:
            raise _Configured
        raise ControllerFileError(f"{self._path}: main(spinner) uses spinner.{name} before spinner.configure(...): "
                                  "expected the norm functions configured first (or write them as column "
                                  "expressions, docs/telemetry.md)")


def _identity_speed(speed: float, angle: float) -> float:
    return speed


def _identity_angle(speed: float, angle: float) -> float:
    return angle


def controller_norms(path: str | Path, *, wall_limit_s: float = 10.0) -> dict[str, NormFn]:
    """``{"speed_norm": f, "turn_norm": g}`` (``(speed, angle)`` in the controller's units ->
    m/s, rad) as the Python controller at ``path`` configures them; a controller that
    returns without configuring any speaks m/s and radians (identities). Raises
    :class:`~simrunner.errors.ControllerFileError` (one line) for a C/C++ controller, one
    that builds ``Spinner(...)`` itself, one that fails before configuring (its traceback's
    last line and file:line), one that calls ``os._exit`` (kept from ending the process) or
    one still running after ``wall_limit_s`` of wall time (from the main thread only: an
    alarm) without using the Spinner after configuring."""
    path = Path(path)
    if path.suffix != ".py":
        raise ControllerFileError(f"{path}: expected a Python controller (.py) for --norms; a C or C++ "
                                  "controller's norm functions are written as column expressions")
    controller = load_controller(path)
    probe = _Stand_in(path)
    import os
    import signal
    import threading

    def no_exit(code=0):
        raise _OsExit(code)

    def too_long(signum, frame):
        raise _TooLong

    real_exit, os._exit = os._exit, no_exit
    alarm = threading.current_thread() is threading.main_thread()
    if alarm:
        old = signal.signal(signal.SIGALRM, too_long)
        signal.setitimer(signal.ITIMER_REAL, float(wall_limit_s))
    try:
        with controller.loaded() as main:
            main(probe)
    except _Configured:
        return dict(probe.norms or {})
    except _TooLong:
        if probe.norms is not None:  # configured, then a loop that never uses the spinner
            return dict(probe.norms)
        raise ControllerFileError(f"{path}: main(spinner) ran {wall_limit_s:g} s without configuring its "
                                  "norms or using the spinner: expected spinner.configure(...) first") from None
    except ControllerFileError:
        raise
    except SystemExit as exc:
        if probe.norms is not None:
            return dict(probe.norms)
        call = "os._exit" if isinstance(exc, _OsExit) else "sys.exit"
        raise ControllerFileError(f"{path}: main(spinner) called {call}({exc.code!r}) before configuring its "
                                  "norms: expected spinner.configure(...) first") from None
    except Exception as exc:  # noqa: BLE001 - the user's code: any fault is reported
        if probe.norms is not None:  # after configuring: the norms are known
            return dict(probe.norms)
        last = user_traceback(exc).rstrip().splitlines()
        frames = [ln.strip() for ln in last if ln.strip().startswith("File ")]
        where = f" ({frames[-1]})" if frames else ""
        if "needs a running simulation" in str(exc):
            raise ControllerFileError(f"{path}: main builds Spinner(...) itself: expected "
                                      "spinner.configure(speed_norm=..., turn_norm=...) for --norms, or the "
                                      "norm functions written as column expressions") from None
        raise ControllerFileError(f"{path}: main(spinner) failed before configuring its norms: "
                                  f"{type(exc).__name__}: {exc}{where}") from None
    finally:
        os._exit = real_exit
        if alarm:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, old)
    return dict(probe.norms or {"speed_norm": _identity_speed, "turn_norm": _identity_angle})


__all__ = ["controller_norms"]
