"""``simrunner check CONTROLLER``: a thin click layer over
:func:`simrunner.run.check.check_controller`.

Exit codes: 0 no problems (warnings may be printed); 1 problems; 2 bad input (one line).
"""
from __future__ import annotations

import sys

import click


@click.command("check")
@click.argument("controller", type=click.Path(exists=True, dir_okay=False, path_type=str))
@click.option("--track", default=None, metavar="LAYOUT|DIR|WORLD",
              help="Track to check on (default: the bundled thesis figure-8).")
@click.option("--car", default=None, metavar="CAR.toml", help="Car description (default: built-in car).")
@click.option("--seconds", default=3.0, show_default=True,
              type=click.FloatRange(min=0, max=600, min_open=True), metavar="SECONDS",
              help="Simulated time of each of the two check runs.")
@click.option("--wall-limit", "wall_limit_s", default=3.0, show_default=True,
              type=click.FloatRange(min=0, min_open=True), metavar="SECONDS",
              help="Wall time without simulated progress before a controller counts as stalled.")
def check_cmd(controller, track, car, seconds, wall_limit_s) -> None:
    """Run CONTROLLER briefly (twice, same seed) and report what breaks the controller
    contract: faults with file:line, stalls, nondeterminism, bad or capped commands."""
    from simrunner.cli import input_errors
    from simrunner.run.check import check_controller

    try:
        report = check_controller(controller, track=track, car=car, seconds=seconds,
                                  wall_limit_s=wall_limit_s)
    except input_errors() as exc:
        click.echo(f"simrunner: {exc}", err=True)
        sys.exit(2)
    click.echo(report.text(), nl=False)
    sys.exit(0 if report.ok else 1)
