"""Headless, deterministic NXP Cup car simulator with the thesis's Spinner API.

``simrunner drive controller.py`` runs ``main(spinner)`` of a controller file against the
dartpy car on a track; :func:`drive` is the same from Python. Heavy modules (dartpy) load
only when :func:`drive` is first used.

Layout (the folders follow one run; nothing imports a folder listed after it):

- ``simrunner.errors``     the exception root :class:`SimError` and its subclasses
- ``simrunner.track``      the simulator's track: raster, start pose, lap gate
- ``simrunner.car``        the car model: dartpy body and physics, effects
- ``simrunner.sensors``    the cameras: line camera, physical imaging, the Pixy2
- ``simrunner.telemetry``  the run log: schema, reading, writing, streaming, column maps
- ``simrunner.reports``    what a run leaves to read: plot, debug video, the output files
- ``simrunner.run``        one run: clock, Spinner, judge, controllers, drive
- ``simrunner.workflows``  excitation plans, calibration, the sim-vs-real gap
- ``simrunner.cli``        the ``simrunner`` command
"""
from simrunner.errors import CommandError, ControllerError, RunFinished, SimError
from simrunner.run.spinner import Spinner

__all__ = ["SimError", "ControllerError", "CommandError", "RunFinished", "Spinner", "drive",
           "RunResult", "RunSettings", "Outcome", "RunLog", "read_log", "write_log"]

_LAZY = {"drive": "simrunner.run.runner", "RunResult": "simrunner.run.result",
         "Outcome": "simrunner.run.result", "RunSettings": "simrunner.run.settings",
         "RunLog": "simrunner.telemetry.log", "read_log": "simrunner.telemetry.log",
         "write_log": "simrunner.telemetry.log"}


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'simrunner' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(module), name)
