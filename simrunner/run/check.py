"""The controller checker: run a controller briefly and tell what breaks the contract.

In the spirit of Gymnasium's ``env_checker``: :func:`check_controller` loads the controller,
drives it twice for a short simulated time with the same seed, and reports

- problems (the controller cannot work here): the file does not load or has no usable
  ``main(spinner)``; ``main`` raises (with the user's file:line); it never lets simulated time
  pass (stalled); it sends bad commands; two runs with the same seed differ (hidden wall-clock
  time, an unseeded random generator, state kept between runs);
- warnings (it runs, but probably not as meant): it reads the computer's clock or seeds randomness
  from it (file:line, :mod:`simrunner.run.hostclock`), delays with an empty counting loop
  (:mod:`simrunner.run.delayloops`), ``main`` returns early, the car never moves,
  commands beyond the car's limits (capped), the car leaves the track in the check window.

``simrunner check CONTROLLER`` prints the report; exit 0 without problems, 1 with.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simrunner.errors import ControllerFileError
from simrunner.run.controller import load_controller, user_location
from simrunner.run.result import Outcome, RunResult
from simrunner.run.runner import Run, resolve_track
from simrunner.run.settings import RunSettings
from simrunner.track import SimTrack
from vehicle.description import CarDescription, load_car

CHECK_SECONDS = 3.0
CHECK_WALL_LIMIT_S = 3.0


@dataclass(frozen=True)
class CheckReport:
    """What :func:`check_controller` found; ``ok`` when there are no problems."""

    controller: str
    problems: tuple[str, ...]
    warnings: tuple[str, ...]
    sim_time_s: float = 0.0
    runs: int = 0

    @property
    def ok(self) -> bool:
        return not self.problems

    def text(self) -> str:
        runs = {0: "not run", 1: "one run", 2: "two runs"}.get(self.runs, f"{self.runs} runs")
        lines = [f"{self.controller}: {'OK' if self.ok else 'PROBLEMS'} "
                 f"({runs}, {self.sim_time_s:.2f} s simulated)"]
        lines += [f"  problem: {p}" for p in self.problems]
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines) + "\n"


def _run_once(controller, track: SimTrack, car: CarDescription, settings: RunSettings) -> RunResult:
    run = Run(track, car, settings)
    outcome, message, error = run.execute(controller)
    return RunResult(outcome=outcome, laps=settings.laps, laps_completed=run.judge.laps_completed,
                     lap_times_s=run.judge.lap_times_s, sim_time_s=run.clock.time_s,
                     wall_time_s=run.wall_time_s, track=str(track.source), seed=settings.seed,
                     message=message, error=error, log=run.recorder.freeze("<check>"),
                     warnings=run.warnings)


def _first_difference(a, b) -> str | None:
    if len(a) != len(b):
        return f"{len(a)} vs {len(b)} frames"
    for name in ("speed_cmd_mps", "steer_cmd_rad", "x_m", "y_m", "yaw_rad"):  # causes first
        x, y = getattr(a, name), getattr(b, name)
        diff = np.flatnonzero(x != y)
        if diff.size:
            k = int(diff[0])
            return f"{name} differs first at frame {k} (t = {a.t_s[k]:.3f} s)"
    return None


def check_controller(controller, *, track: str | Path | SimTrack | None = None,
                     car: str | Path | CarDescription | None = None, seconds: float = CHECK_SECONDS,
                     seed: int = 0, wall_limit_s: float = CHECK_WALL_LIMIT_S,
                     params: dict | None = None) -> CheckReport:
    """Check ``controller`` (a file, a callable or a built C/C++ ``NativeProgram``) on ``track``
    (default: the bundled one), with the run parameters ``params`` (``--param``).

    Bad input (missing track, bad car file, bad settings) raises as in :func:`drive`; a bad
    controller file is a problem in the report.
    """
    sources = getattr(controller, "sources", None)  # a NativeProgram: its sources (not a kit's) name it
    if sources is not None:
        from simrunner.run.native.build import KITS_DIR

        own = [str(p) for p in sources if KITS_DIR not in Path(p).resolve().parents]
        name = ", ".join(own) or str(controller.library)
    else:
        name = str(controller) if not callable(controller) else getattr(controller, "__qualname__", "main")
    car_desc = car if isinstance(car, CarDescription) else load_car(car)
    settings = RunSettings(laps=1000, time_limit_s=seconds, seed=seed, wall_limit_s=wall_limit_s,
                           params=params or {})
    sim_track, _ = resolve_track(track, car_desc)
    ctrl = None
    try:
        ctrl = load_controller(controller)
        first = _run_once(ctrl, sim_track, car_desc, settings)
        second = None
        if first.outcome not in (Outcome.CONTROLLER_ERROR, Outcome.STALLED):
            second = _run_once(ctrl, sim_track, car_desc, settings)
    except ControllerFileError as exc:
        return CheckReport(name, (str(exc),), () if ctrl is None else tuple(ctrl.load_warnings()))
    finally:
        if ctrl is not None:
            ctrl.close()  # (a C controller's libraries unloaded now)
    problems: list[str] = []
    # where it reads the computer's clock or delays with an empty loop (found at its load), first: the
    # likely cause of what follows
    clock = ctrl.load_warnings()
    warnings: list[str] = list(clock)
    if first.outcome == Outcome.CONTROLLER_ERROR:
        where = _user_location(first)
        message = first.message  # (drive's outcome message may end with the same place: said once)
        if where and message.endswith(where):
            message = message[:-len(where)]
        problems.append(f"main raised{where}: {message}")
    elif first.outcome == Outcome.STALLED:
        problems.append(first.message)
    elif first.outcome == Outcome.CONTROLLER_RETURNED:
        warnings.append(f"main returned after {first.sim_time_s:.2f} s of simulated time; a "
                        f"controller normally loops until the run ends")
    elif first.outcome == Outcome.OFF_TRACK:
        warnings.append(f"the car left the track in the first {seconds:g} s: {first.message}")
    elif first.outcome == Outcome.OFF_COURSE:
        warnings.append(f"the car left the course in the first {seconds:g} s: {first.message}")
    elif first.outcome == Outcome.TOUCHED:
        warnings.append(f"the car touched an object on the track in the first {seconds:g} s: {first.message}")
    if second is not None:
        diff = _first_difference(first.log, second.log)
        if diff is not None or first.outcome != second.outcome:
            problems.append("two runs with the same seed differ ("
                            f"{diff or f'{first.outcome} vs {second.outcome}'}): use the Spinner's "
                            "time (get_time) instead of the wall clock, and seed any random "
                            "generator; keep no state between runs")
    log = first.log
    if len(log) > 1 and first.outcome not in (Outcome.CONTROLLER_ERROR, Outcome.STALLED):
        if not np.any(log.speed_cmd_mps != 0.0):
            warnings.append(f"no speed was ever commanded: the car does not move ({_speed_calls(ctrl)})")
        vmax, dmax = car_desc.drive.max_speed_mps, car_desc.steering.limit_rad
        v = float(np.max(np.abs(log.speed_cmd_mps)))
        if v > vmax:
            warnings.append(f"speed commands up to {v:.3g} m/s exceed the car's max_speed_mps "
                            f"{vmax:g} (they are capped)")
        d = float(np.max(np.abs(log.steer_cmd_rad)))
        if d > dmax:
            warnings.append(f"steering commands up to {d:.3g} rad exceed the car's limit "
                            f"{dmax:g} rad (they are capped); check turn_norm's units")
    # the run's own warnings (a kit's: a timer whose IRQ is off; threads left running), but the
    # speed cap's, which the lines above say for the whole run
    warnings += [w for w in first.warnings if not w.startswith(("speed command ", "duty command ")) and w not in clock]
    return CheckReport(name, tuple(problems), tuple(warnings), first.sim_time_s,
                       1 if second is None else 2)


#: what sets the speed, by the --kit a C/C++ program was built against (docs/firmware.md)
_KIT_SPEED_CALLS = {
    "tfc": "set the motors' duties with TFC_SetMotorPWM after TFC_HBRIDGE_ENABLE",
    "tfc-mbed": "set the motors' duties with TFC_SetMotorPWM after TFC_HBRIDGE_ENABLE",
    "s32k144": "drive the motors with HbridgeSetSpeed or EscSetSpeed after their Init",
}


def _speed_calls(ctrl) -> str:
    """How the controller ``ctrl`` sets a speed, in its own language and kit."""
    program = getattr(ctrl.main, "program", None)  # (a C/C++ program's: NativeController)
    if program is None:
        return "call set_speed or set_speed_and_servo"
    if program.kit in _KIT_SPEED_CALLS:
        return _KIT_SPEED_CALLS[program.kit]
    if any(Path(src).suffix.lower() in (".cpp", ".cc", ".cxx", ".c++") for src in program.sources):
        return "call setSpeed or setSpeedAndServo (spinner.hpp), or spinner_set_speed"
    return "call spinner_set_speed or spinner_set_speed_and_servo"


def _user_location(result: RunResult) -> str:
    """`` at FILE:LINE`` of the innermost user frame of the traceback, if any."""
    if result.error is None:
        return ""
    loc = user_location(result.error.traceback_text)
    return f" at {loc}" if loc else ""
