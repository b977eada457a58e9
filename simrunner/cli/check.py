"""``simrunner check CONTROLLER``: a thin click layer over
:func:`simrunner.run.check.check_controller`.

Exit codes: 0 no problems (warnings may be printed); 1 problems; 2 bad input (one line).
A C/C++ program is checked isolated (as ``drive --isolate`` runs it): no supervisor watches this
process, which a program's constructors, run as its library loads, could end.
"""
from __future__ import annotations

import sys

import click

from simrunner.cli import build_options
from simrunner.cli.names import HELP

@click.command("check", context_settings=HELP)
@click.argument("controller", type=click.Path(exists=True, dir_okay=False, path_type=str))
@click.argument("more_sources", nargs=-1, type=click.Path(exists=True, dir_okay=False, path_type=str))
@click.option("--track", default=None, metavar="LAYOUT|DIR|WORLD",
              help="Track to check on (default: the bundled thesis figure-8).")
@click.option("--car", default=None, metavar="CAR.toml", help="Car description (default: built-in car).")
@click.option("--seconds", default=3.0, show_default=True,
              type=click.FloatRange(min=0, max=600, min_open=True), metavar="SECONDS",
              help="Simulated time of each of the two check runs.")
@click.option("--wall-limit", "wall_limit_s", default=3.0, show_default=True,
              type=click.FloatRange(min=0, min_open=True), metavar="SECONDS",
              help="Wall time without simulated progress before a controller counts as stalled.")
@click.option("--param", "params", multiple=True, metavar="NAME=VALUE",
              help="Controller parameter, as for drive (repeatable).")
@build_options
def check_cmd(controller, more_sources, track, car, seconds, wall_limit_s, params=(), include_dirs=(),
              defines=(), kit=None, isrs=()) -> None:
    """Run CONTROLLER briefly (twice, same seed) and report what breaks the controller
    contract: faults with file:line, stalls, nondeterminism, bad or capped commands. C/C++
    firmware: its sources and the options that build it, as for drive."""
    from simrunner.cli import _builds_native, _native_program, input_errors
    from simrunner.run.check import check_controller
    from simrunner.run.params import parse_params

    try:
        # a C/C++ program runs isolated (as drive's --isolate): check has no supervisor, and in its
        # process the program's constructors, run as its library loads, could end it (a fault, an exit)
        program = _native_program(controller, tuple(more_sources), tuple(include_dirs), tuple(defines),
                                  _builds_native(controller, more_sources, include_dirs, defines), kit, tuple(isrs))
        report = check_controller(program, track=track, car=car, seconds=seconds,
                                  wall_limit_s=wall_limit_s, params=parse_params(params))
    except input_errors() as exc:
        click.echo(f"simrunner: {exc}", err=True)
        sys.exit(2)
    click.echo(report.text(), nl=False)
    sys.exit(0 if report.ok else 1)
