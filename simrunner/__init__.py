"""Headless, deterministic NXP Cup car simulator with the thesis's Spinner API.

``simrunner drive controller.py`` runs ``main(spinner)`` of a controller file against the
dartpy car on a track; :func:`drive` is the same from Python. Heavy modules (dartpy) load
only when :func:`drive` is first used.
"""
from .errors import CommandError, ControllerError, RunFinished, SimError
from .spinner import Spinner

__all__ = ["SimError", "ControllerError", "CommandError", "RunFinished", "Spinner", "drive",
           "RunResult"]


def __getattr__(name: str):
    if name in ("drive", "RunResult"):
        from . import runner

        return getattr(runner, name)
    raise AttributeError(f"module 'simrunner' has no attribute {name!r}")
