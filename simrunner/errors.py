"""Exceptions of the simulator runner (one root: :class:`SimError`).

``SimError`` and its subclasses are ordinary exceptions: bad input (track, car, controller
file, options) and bad commands. The two *run-control* signals derive from
``BaseException`` on purpose, so a controller's ``except Exception:`` cannot swallow them:

- :class:`RunFinished` — the run is over (laps done, time limit, off track, watchdog);
  raised by the next Spinner call, it unwinds the controller's ``main``.
- :class:`Stalled` (a ``RunFinished``) — raised by the wall-clock watchdog into a
  controller that stopped calling the Spinner.
"""
from __future__ import annotations


class SimError(Exception):
    """Root of the simulator's errors (bad input, bad command, failed run)."""


class ControllerFileError(SimError):
    """The controller file is missing, not Python, or has no usable ``main(spinner)``."""


class CommandError(SimError, ValueError):
    """A Spinner method got a value it cannot use (NaN/inf command, row out of range, ...).

    The message names the method and the value, e.g. ``set_speed(speed=nan): ...``.
    """


class ControllerError(SimError):
    """The controller raised. ``traceback_text`` is its traceback with the simulator's own
    frames removed (the user's frames only); ``str(err)`` is the last line."""

    def __init__(self, message: str, traceback_text: str = ""):
        super().__init__(message)
        self.traceback_text = traceback_text


class RunFinished(BaseException):
    """The run is over; ``outcome`` is the value of a ``simrunner.run.result.Outcome`` that
    ends a run from inside it (``"finished"``, ``"off_track"``, ``"timeout"``, ``"stalled"``,
    ``"controller_error"``); ``controller_returned`` and ``interrupted`` need no signal."""

    def __init__(self, outcome: str, message: str = ""):
        super().__init__(message or outcome)
        self.outcome = outcome
        self.message = message or outcome


class Stalled(RunFinished):
    """The controller ran for the wall-clock limit without calling into the Spinner."""

    def __init__(self, message: str):
        super().__init__("stalled", message)


class CameraError(SimError, ValueError):
    """The camera got a setting or request it cannot use (``supersample`` below 1, an image
    row outside ``0..H-1``); the message names the value and the valid range."""
