"""``simrunner`` command line: thin click layers over importable functions.

``drive`` (here, over :func:`simrunner.run.runner.drive`), ``check``
(:mod:`simrunner.cli.check`), ``excite`` and ``calibrate`` (:mod:`simrunner.cli.calib`),
``gap`` (:mod:`simrunner.cli.gap`); those load on use, so ``--help`` stays quick.

Exit codes of ``drive``: 0 the run finished its laps or ``main`` returned (or called
``sys.exit(0)``); 1 the run failed (off track, timeout, controller error or non-zero
``sys.exit``, stalled, or stuck inside one C call - see simrunner.run.watchdog; ``drive``
runs the simulation in a child process it supervises, which writes the outputs of such a
run: simrunner.run.supervise); 2 bad input,
or a simulator dependency is not installed (one line on stderr, no traceback); 130
interrupted by Ctrl-C, 143 by SIGTERM, 129 by SIGHUP (outputs are still written).
"""
from __future__ import annotations

import sys

import click

from simrunner.cli.names import HELP

from simrunner.errors import SimError
from simrunner.run.rules import EVENT_NAMES


def input_errors() -> tuple[type[BaseException], ...]:
    """The package exception roots that mean bad input."""
    roots: list[type[BaseException]] = [SimError]
    from vehicle.description import CarDescriptionError

    roots.append(CarDescriptionError)
    try:
        from worlds import WorldError

        roots.append(WorldError)
    except ImportError:  # pragma: no cover - module not built yet
        pass
    try:
        from trackgen import TrackError

        roots.append(TrackError)
    except ImportError:  # pragma: no cover
        pass
    return tuple(roots)


# The simulator's own dependencies (pyproject.toml; the track tools need none of them):
# import name -> distribution. An installation without one is bad input, not a bug.
SIM_DEPENDENCIES = {"dartpy": "dartpy", "cv2": "opencv-python-headless", "av": "av", "numba": "numba",
                    "llvmlite": "numba", "scipy": "scipy", "tqdm": "tqdm"}


def _missing_dependency(exc: ModuleNotFoundError) -> str | None:
    """The one line for a missing simulator dependency (None: some other module)."""
    module = (exc.name or "").partition(".")[0]
    dist = SIM_DEPENDENCIES.get(module)
    if dist is None:
        return None
    what = dist if dist == module else f"{dist} (module {module})"
    return f"simrunner: the simulator needs {what}, which is not installed: pip install {dist}"


class _LazyGroup(click.Group):
    """Loads the workflow commands (scipy-heavy) only when they are used: ``simrunner --help``
    lists them with the docstrings of their functions, read from the source without
    importing it."""

    LAZY = {"check": ("simrunner.cli.check", "check_cmd"),
            "calibrate": ("simrunner.cli.calib", "calibrate_cmd"),
            "calibrate-camera": ("simrunner.cli.calib", "calibrate_camera_cmd"),
            "excite": ("simrunner.cli.calib", "excite_cmd"),
            "gap": ("simrunner.cli.gap", "gap"),
            "batch": ("simrunner.cli.batch", "batch_cmd"),
            "plot": ("simrunner.cli.plot", "plot_cmd")}
    _listing = False

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(set(super().list_commands(ctx)) | set(self.LAZY))

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        self._listing = True
        try:
            super().format_commands(ctx, formatter)
        finally:
            self._listing = False

    def invoke(self, ctx: click.Context):
        """Run the command; a simulator dependency that is not installed is one line, exit 2.
        The simulator's own warnings (a log read with a line left out, a column not read)
        print as ``simrunner: warning: ...`` lines, not as Python's warning format. A reader
        of stdout that goes away (``| head``) ends nothing early and shows no traceback
        (:mod:`simrunner.cli.pipes`)."""
        import warnings

        from simrunner.cli.pipes import tolerate_reader_leaving

        tolerate_reader_leaving()
        shown = warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None):
            if getattr(category, "__module__", "").startswith(("simrunner.", "trackgen.", "worlds.", "vehicle.")):
                click.echo(f"simrunner: warning: {message}", err=True)
            else:
                shown(message, category, filename, lineno, file, line)

        warnings.showwarning = show
        try:
            return super().invoke(ctx)
        except ModuleNotFoundError as exc:
            line = _missing_dependency(exc)
            if line is None:
                raise
            click.echo(line, err=True)
            sys.exit(2)
        finally:
            warnings.showwarning = shown

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name in self.LAZY:
            module, attr = self.LAZY[name]
            doc = _function_docstring(module, attr) if self._listing else None
            if doc is not None:  # only the help text is wanted: a stand-in command
                return click.Command(name, help=doc)
            import importlib

            return getattr(importlib.import_module(module), attr)
        return super().get_command(ctx, name)


def _function_docstring(module: str, function: str) -> str | None:
    """The docstring of top-level ``function`` of ``module``, read without importing it
    (None if it cannot be found: the caller then imports the module)."""
    import ast
    import importlib.util
    from pathlib import Path

    try:
        spec = importlib.util.find_spec(module)
        tree = ast.parse(Path(spec.origin).read_text(encoding="utf-8"))
    except (ImportError, AttributeError, TypeError, OSError, SyntaxError, ValueError):
        return None
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == function:
            return ast.get_docstring(node, clean=False)
    return None


@click.group(cls=_LazyGroup, context_settings=HELP)
@click.version_option(package_name="nxpcup-sim", prog_name="simrunner")
def main() -> None:
    """Headless NXP Cup car simulator with the thesis's Spinner API."""
    _no_collection_at_exit()


def run() -> None:
    """The ``simrunner`` program (pyproject's entry point): :data:`main` on ``sys.argv``, and
    the end of the process. A command that ran none of the user's code in this process and
    left nothing open (``batch`` with its local workers: :func:`end_without_teardown`) ends
    it without the interpreter's teardown: the exit handlers run, the streams are flushed,
    then ``os._exit`` - ~20 ms less at the end of every ``simrunner batch``, which freeing
    numpy's, dartpy's and OpenCV's modules and objects costs and nothing reads. Everywhere
    else (and under ``CliRunner``, which calls :data:`main`) the interpreter ends as usual."""
    process = {"end_without_teardown": False}
    try:
        main(obj=process)
    except SystemExit as exc:
        if not process["end_without_teardown"]:
            raise
        _end_process(exc.code)


def end_without_teardown(ctx: click.Context) -> None:
    """Called by a command as it returns: this process may end without the interpreter's
    teardown (:func:`run`), if it is the ``simrunner`` program (not a ``CliRunner``) and only
    this thread runs (a thread left - Ray's, a progress bar's - gets the usual end)."""
    import threading

    process = ctx.find_root().obj
    if isinstance(process, dict) and "end_without_teardown" in process and threading.active_count() == 1:
        process["end_without_teardown"] = True


def _end_process(code) -> None:
    """End the process with ``sys.exit(code)``'s status: exit handlers, flushed streams, no
    teardown."""
    import atexit
    import os

    if code is None:
        status = 0
    elif isinstance(code, int):
        status = code & 0xFF
    else:  # (as Python: a message on stderr, status 1)
        print(code, file=sys.stderr)
        status = 1
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # (a reader gone, a stream closed: as Python's end)
            pass
    if "ctypes" in sys.modules:  # C code's buffered output too, as exit() flushes it
        import ctypes

        ctypes.CDLL(None).fflush(None)
    os._exit(status)


def _no_collection_at_exit() -> None:
    """Freeze the garbage collector at exit (:func:`gc.freeze` as an atexit handler): the
    interpreter's final collections then skip every object, ~20 ms of CPU at the end of
    ``drive`` and ~35 ms at the end of ``batch`` (numpy, dartpy and OpenCV leave many). Objects
    are still freed by their reference counts; only reference cycles left at exit go
    uncollected, whose finalisers Python does not promise to run anyway. (Idempotent: a test
    process that invokes the command many times registers it once.)"""
    import atexit
    import gc

    atexit.unregister(gc.freeze)
    atexit.register(gc.freeze)


class McuTime(click.ParamType):
    """``--mcu-time``: ``measured`` or seconds per call, kept as typed (the run's settings check
    the range); an option's name in its place (``--mcu-time --laps 2``) is named as the value."""

    name = "measured|SECONDS"

    def convert(self, value, param, ctx):
        if value is None or value == "measured" or not isinstance(value, str):
            return value
        try:
            float(value)
        except ValueError:
            missing = " (the option's value is missing)" if value.startswith("-") else ""
            self.fail(f"{value!r}: expected measured or seconds per call, e.g. 0.002{missing}", param, ctx)
        return value


def build_options(command):
    """The options that build a C/C++ controller or kit firmware (-I, -D, --kit, --isr), alike
    for ``drive``, ``check`` and ``batch``."""
    for option in reversed((
            click.option("-I", "--include", "include_dirs", multiple=True, metavar="DIR",
                         help="C/C++ controllers: an include directory (repeatable)."),
            click.option("-D", "--define", "defines", multiple=True, metavar="NAME[=VALUE]",
                         help="C/C++ controllers: a preprocessor define (repeatable)."),
            click.option("--kit", default=None, metavar="tfc|tfc-mbed|s32k144",
                         help="C/C++ firmware: build it against this kit library's implementation on "
                              "the simulated car (tfc: the FRDM-TFC library; tfc-mbed: its mbed "
                              "flavour, C++; s32k144: the NXP Cup S32K144 kit's drivers; "
                              "docs/firmware.md)."),
            click.option("--isr", "isrs", multiple=True, metavar="NAME@HZ",
                         help="C/C++ firmware: call your function NAME (void NAME(void), e.g. your "
                              "timer's LPTimer_IRQHandler) HZ times a second of simulated time, as its "
                              "timer interrupt would (repeatable; docs/firmware.md, Timer "
                              "interrupts)."))):
        command = option(command)
    return command


@main.command("drive", context_settings=HELP)
@click.argument("controller", type=click.Path(dir_okay=False, path_type=str))
@click.argument("more_sources", nargs=-1, type=click.Path(dir_okay=False, path_type=str))
@click.option("--track", default=None, metavar="LAYOUT|DIR|WORLD|default|floor",
              help="Track: layout .txt, trackgen folder, world file or Gazebo model folder; "
                   "'default': the bundled thesis figure-8 (the default); 'floor': an empty floor, no judging.")
@click.option("--laps", default=1, show_default=True, type=click.IntRange(min=1),
              help="Laps to complete.")
@click.option("--time-limit", "time_limit_s", default=None,
              type=click.FloatRange(min=0, min_open=True), metavar="SECONDS",
              help="Simulated-time limit of the run [default: max(60, laps x lap length / "
                   "0.5 m/s)].")
@click.option("--start", "start", default=None, metavar="X,Y,YAW",
              help="Start pose of the car (rear-axle midpoint): x, y in metres, heading in "
                   "degrees (counter-clockwise from +x).")
@click.option("--start-before-finish", "start_before_finish_m", default=None,
              type=click.FloatRange(min=0, max=1e4), metavar="METRES",
              help="Start on the track's centre with the front bumper this far before the "
                   "finish line (thesis Fig. 5.2).")
@click.option("--keep-driving", is_flag=True, default=False,
              help="Leaving the track or the course does not end the run (still recorded: "
                   "off_track column, a warning).")
@click.option("--off-track-wheels", "off_track_wheels", default=None,
              type=click.IntRange(1, 4), metavar="N",
              help="Wheels off the road that end the run [default: 3, the rules' race; 1 in the "
                   "other disciplines: any wheel].")
@click.option("--event", default=None, type=click.Choice(EVENT_NAMES),
              help="Run a discipline as the rules do, on its own layout unless --track: race (one "
                   "timed lap, 120 s, +1 s without a stop within 2 m), figure8, speed_limit; "
                   "docs/events.md (default: practice, --laps).")
@click.option("--video", default=None, metavar="PATH.mp4", help="Write the debug video.")
@click.option("--video-fps", "video_fps", default=None, type=click.FloatRange(min=0, max=1000, min_open=True),
              metavar="FPS", help="The debug video's highest frame rate (default 30: every second frame of "
                                  "the 50 fps camera; 50: every frame, slower to write). It plays in "
                                  "simulated time, whatever period the camera's frames come at.")
@click.option("--csv", default=None, metavar="PATH", help="Write telemetry (one row per camera frame).")
@click.option("--plot", default=None, metavar="PATH.png", help="Write path/speed/steering plot.")
@click.option("--summary", default=None, metavar="PATH.json", help="Write the run summary as JSON.")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0),
              help="Seed of the camera-noise generator.")
@click.option("--car", default=None, metavar="CAR.toml", help="Car description (default: built-in car).")
@click.option("--dt", "dt_s", default=0.002, show_default=True,
              type=click.FloatRange(min=0, max=0.02, min_open=True), metavar="SECONDS",
              help="Physics time step.")
@click.option("--wall-limit", "wall_limit_s", default=10.0, show_default=True,
              type=click.FloatRange(min=0, min_open=True), metavar="SECONDS",
              help="Stop a controller that spends this much wall time without letting "
                   "simulated time pass.")
@click.option("--watch", is_flag=True,
              help="Keep the track loaded and run again each time CONTROLLER is saved (Ctrl-C ends).")
@click.option("--param", "params", multiple=True, metavar="NAME=VALUE",
              help="Controller parameter, read with spinner.param(NAME, default) (C: spinner_param); repeatable.")
@build_options
@click.option("--isolate", is_flag=True,
              help="C/C++ controllers: run in a child process instead of the simulator's (slower; "
                   "code that overwrites memory cannot touch the simulator). A .so always is.")
@click.option("--mcu-time", "mcu_time", default=None, type=McuTime(), metavar="measured|SECONDS",
              help="The controller's own processing costs simulated time, as on the car: its CPU time "
                   "between Spinner calls times --mcu-scale (measured: not deterministic), or SECONDS "
                   "per call (docs/drive.md).")
@click.option("--mcu-scale", "mcu_scale", default=1.0, show_default=True,
              type=click.FloatRange(min=0, max=1e4, min_open=True), metavar="FACTOR",
              help="With --mcu-time measured: how many times slower the car's MCU runs the code than "
                   "this machine (docs/drive.md has estimates per kit).")
def drive_cmd(controller, more_sources, track, laps, time_limit_s, video, csv, plot, summary, seed,
              car, dt_s, wall_limit_s, params, include_dirs, defines, start, start_before_finish_m,
              keep_driving, off_track_wheels=None, event=None, watch=False, isolate=False,
              mcu_time=None, mcu_scale=1.0, kit=None, video_fps=None, isrs=()) -> None:
    """Run CONTROLLER on the simulated car: a .py file defining main(spinner), or C/C++
    sources (.c, .cpp; several allowed) with main() - compiled with debug info, cached - or
    a shared library (.so). See docs/c_controllers.md."""
    from simrunner.run.params import parse_params
    from simrunner.run.faults import Terminated, exit_code
    from simrunner.run.runner import drive

    if watch:
        from simrunner.cli.watch import watch_drive

        try:
            params = parse_params(params)
        except input_errors() as exc:
            click.echo(f"simrunner: {exc}", err=True)
            sys.exit(2)
        native = {}
        if more_sources or include_dirs or defines or isolate or kit or isrs or not controller.endswith(".py"):
            if controller.endswith(".so"):
                click.echo("simrunner: --watch: a .so is built elsewhere: watch its sources instead", err=True)
                sys.exit(2)
            from simrunner.run.watch import native_watched

            # isolated (as --isolate): a watch session has no supervisor, and in its process a program's
            # constructors, run as its library loads, could end it (a fault, an exit: docs/c_controllers.md);
            # each run's program and the threads it leaves end with its child
            builds = _builds_native(controller, more_sources, include_dirs, defines)
            native = dict(make=lambda: _native_program(controller, more_sources, include_dirs, defines,
                                                       isolate or builds, kit, isrs),
                          watched=native_watched(controller, more_sources, include_dirs))
        watch_drive(dict(controller=controller, **native, track=track, laps=laps, time_limit_s=time_limit_s,
                         video=video, video_fps=video_fps, csv=csv, plot=plot, summary=summary, seed=seed, car=car,
                         dt_s=dt_s, wall_limit_s=wall_limit_s, params=params, start=_start_pose(start),
                         start_before_finish_m=start_before_finish_m, keep_driving=keep_driving,
                         off_track_wheels=off_track_wheels, event=event, mcu_time=mcu_time,
                         mcu_scale=mcu_scale))

    start_pose = _start_pose(start)  # a usage error (click's), before any fork
    strays = []

    def run() -> int:
        try:
            program = _native_program(controller, more_sources, include_dirs, defines, isolate, kit, isrs)
            result = drive(program, track=track, laps=laps, time_limit_s=time_limit_s, video=video, video_fps=video_fps,
                           csv=csv, plot=plot, summary=summary, seed=seed, car=car, dt_s=dt_s,
                           wall_limit_s=wall_limit_s, params=parse_params(params),
                           start=start_pose, start_before_finish_m=start_before_finish_m,
                           keep_driving=keep_driving, off_track_wheels=off_track_wheels, event=event,
                           mcu_time=mcu_time, mcu_scale=mcu_scale)
        except input_errors() as exc:
            click.echo(f"simrunner: {exc}", err=True)
            return 2
        except Terminated as exc:  # before the run started: nothing was written
            click.echo(f"simrunner: {exc.args[0]} received before the run started", err=True)
            return 128 + exc.signum
        except ModuleNotFoundError as exc:  # as _LazyGroup.invoke (this may run in a child)
            line = _missing_dependency(exc)
            if line is None:
                raise
            click.echo(line, err=True)
            return 2
        _print_result(result)
        if result.unused_params:
            from simrunner.run.params import unused_params_text

            click.echo("simrunner: warning: " + unused_params_text(result.unused_params, result.params_read),
                       err=True)
        strays.append(result.stray_threads)
        return exit_code(result.outcome, result.signal)

    from simrunner.run.supervise import can_supervise

    if not can_supervise():
        code = run()
        if any(strays):  # do not wait for the controller's threads at exit
            sys.stdout.flush()
            sys.stderr.flush()
            import os

            os._exit(code)
        sys.exit(code)
    sys.exit(_supervised(run, controller, csv=csv, video=video, plot=plot, summary=summary,
                         track=track, car=car, laps=laps, seed=seed, wall_limit_s=wall_limit_s,
                         video_fps=video_fps))


def _supervised(run, controller: str, *, csv, video, plot, summary, track, car, laps, seed,
                wall_limit_s, video_fps=None) -> int:
    """``run()`` in a supervised child (simrunner.run.supervise); a child ended by the hard
    watchdog or a signal, or by a C/C++ program's end in its constructors as its library loaded
    (the host's report: simrunner.run.postmortem.load_end), gets its outputs written here, from its
    run log. Returns the exit code."""
    from simrunner.reports.outputs import Outputs
    from simrunner.run.faults import exit_code
    from simrunner.run.postmortem import LOAD_END_STATUS, load_end
    from simrunner.run.supervise import remove_temporary, supervise

    end = supervise(run, csv)
    try:
        ended = load_end(end.report, controller) if end.code == LOAD_END_STATUS and not end.stuck else None
        if not end.stuck and end.signal is None and ended is None:
            return end.code
        from simrunner.run.postmortem import StuckRun, finish_dead_run, finish_load_ended_run, finish_stuck_run, \
            stuck_stack

        end.stale_log_removed()  # (an earlier run's CSV where this run's would have been)
        stuck = StuckRun(controller=controller, outputs=Outputs(video=video, csv=csv, plot=plot,
                                                                summary=summary, video_fps=video_fps),
                         track=track, car=car, laps=laps, seed=seed, wall_limit_s=wall_limit_s)
        try:
            if end.stuck:
                click.echo(stuck_stack(end.report, controller), err=True)  # down to the controller's line
                result = finish_stuck_run(stuck, end.report, end.csv_path, wall_time_s=end.wall_time_s,
                                          cpu_time_s=end.cpu_time_s)
            elif ended is not None:  # an exit, spinner_fail, a misused call in a constructor (status 70)
                result = finish_load_ended_run(stuck, ended, end.csv_path, wall_time_s=end.wall_time_s,
                                               cpu_time_s=end.cpu_time_s)
            else:  # killed by a signal the run could not handle (SIGKILL, an uncaught crash)
                result = finish_dead_run(stuck, end.signal, end.csv_path, wall_time_s=end.wall_time_s,
                                         cpu_time_s=end.cpu_time_s, report=end.report)
        except input_errors() as exc:
            click.echo(f"simrunner: {exc}", err=True)
            return 1
        _print_result(result)
        return exit_code(result.outcome, None)  # (1: stalled, killed; an exit(0) at the load: 0)
    finally:
        remove_temporary(end, csv)


def _print_result(result) -> None:
    if result.error is not None:
        click.echo(result.error.traceback_text.rstrip(), err=True)
    for text in result.warnings:
        click.echo(f"warning: {text}", err=True)
    laps_text = ", ".join(f"{t:.2f} s" for t in result.lap_times_s) or "-"
    click.echo(f"outcome: {result.outcome} ({result.message})")
    if result.event is None:
        click.echo(f"laps: {result.laps_completed}/{result.laps}   lap times: {laps_text}")
    else:
        click.echo(f"laps: {result.laps_completed}   lap times: {laps_text}")
        penalties = "".join(f", +{p.seconds:g} s: {p.reason}" for p in result.penalties)
        time_text = "" if result.time_s is None else f", time {result.time_s:.2f} s"
        points = "" if result.points is None else f", {result.points} points"
        click.echo(f"{result.event}: {'passed' if result.passed else 'failed'}{time_text}{points}{penalties}")
    click.echo(f"sim time {result.sim_time_s:.2f} s, wall {result.wall_time_s:.2f} s, "
               f"{result.real_time_factor:.1f}x real time")
    if result.outputs:
        click.echo("wrote: " + ", ".join(result.outputs.values()))


def _start_pose(text: str | None) -> tuple[float, float, float] | None:
    """``--start X,Y,YAW`` (m, m, degrees) -> ``(x_m, y_m, yaw_rad)``; bad text is one line."""
    if text is None:
        return None
    import math

    parts = text.split(",")
    try:
        x, y, yaw_deg = (float(v) for v in parts)
    except ValueError:
        x = y = yaw_deg = math.nan
    if not all(math.isfinite(v) for v in (x, y, yaw_deg)) or len(parts) != 3:
        raise click.BadParameter(f"{text!r}: expected X,Y,YAW (metres, metres, degrees), e.g. 1.5,-0.2,90",
                                 param_hint="'--start'")
    return x, y, math.radians(yaw_deg)


def _native_program(controller: str, more_sources: tuple[str, ...], include_dirs: tuple[str, ...],
                    defines: tuple[str, ...], isolate: bool = False, kit: str | None = None,
                    isrs: tuple[str, ...] = ()):
    """``controller`` itself (Python), or the built C/C++ program (``isolate``: to run in a
    child process; ``isrs``: its ``NAME@HZ`` timer interrupts); compiler warnings are shown on
    stderr. Raises ControllerFileError (bad input) for compile errors."""
    import dataclasses

    from simrunner.errors import ControllerFileError

    timers = [_isr(text) for text in isrs]
    if not _builds_native(controller, more_sources, include_dirs, defines):
        if isolate or kit:
            raise ControllerFileError(f"{controller}: --{'isolate' if isolate else 'kit'} is for C/C++ controllers")
        if timers:
            raise ControllerFileError(f"{controller}: --isr is for C/C++ firmware (in Python: "
                                      f"spinner.every(period_s, handler))")
        return controller
    from simrunner.run.native.build import build_firmware

    program = build_firmware([controller, *more_sources], include_dirs=include_dirs, defines=defines,
                             kit=kit, isrs=timers)
    if program.warnings.strip():
        click.echo(program.warnings.rstrip(), err=True)
    return dataclasses.replace(program, isolate=True) if isolate else program


def _builds_native(controller: str, more_sources, include_dirs, defines) -> bool:
    """Whether :func:`_native_program` builds a C/C++ program of these (else the controller is the
    Python file itself)."""
    return bool(more_sources or include_dirs or defines) or not controller.endswith(".py")


def _isr(text: str) -> tuple[str, float]:
    """``NAME@HZ`` -> ``(NAME, period_s)``; a ControllerFileError naming what was expected."""
    import math
    import re

    from simrunner.errors import ControllerFileError

    name, _, rate = text.partition("@")
    try:
        hz = float(rate)
    except ValueError:
        hz = math.nan
    if not re.fullmatch(r"[A-Za-z_]\w*", name) or not (0 < hz <= 1e5):
        raise ControllerFileError(f"--isr {text}: expected NAME@HZ, a C function name and its rate "
                                  f"(0 < HZ <= 100000), e.g. LPTimer_IRQHandler@100")
    return name, 1.0 / hz


@main.command("cflags", context_settings=HELP)
def cflags_cmd() -> None:
    """Print the compiler flags for building a C/C++ controller by hand (-I<include dir>)."""
    from simrunner.run.native.build import cflags

    click.echo(cflags())


@main.command("include-dir", context_settings=HELP)
def include_dir_cmd() -> None:
    """Print the directory holding spinner.h and spinner.hpp (the C/C++ Spinner API)."""
    from simrunner.run.native.build import INCLUDE_DIR

    click.echo(str(INCLUDE_DIR))


from simrunner.cli.names import add_api_spellings  # noqa: E402  (after the commands)

add_api_spellings(drive_cmd)

if __name__ == "__main__":  # pragma: no cover
    main()
