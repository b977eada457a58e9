"""``simrunner drive --watch``: the drive options, then a run each time the controller file
is saved (:func:`simrunner.run.watch.watch_runs`), with the outcome and lap times printed
after each. Ctrl-C ends it (exit 130); bad track or car input is exit 2 as for ``drive``. C/C++
programs run isolated (``drive_cmd`` builds them so): the session outlives its runs, with no
supervisor, and a program's constructors, run as its library loads, could end its process."""
from __future__ import annotations

import sys
import time
from typing import Any

import click


def _report(event) -> None:
    took = time.perf_counter() - event.saved_at
    head = f"[run {event.number}]"
    if event.error is not None:
        click.echo(f"{head} {event.error}", err=True)
        click.echo(f"{head} waiting for the next save")
        return
    r = event.result
    if r.error is not None:
        click.echo(r.error.traceback_text.rstrip(), err=True)
    laps = ", ".join(f"{t:.2f} s" for t in r.lap_times_s) or "-"
    click.echo(f"{head} outcome: {r.outcome} ({r.message})")
    click.echo(f"{head} laps: {r.laps_completed}/{r.laps}   lap times: {laps}   "
               f"(sim {r.sim_time_s:.2f} s, {took:.2f} s after the save)")
    if r.outputs:
        click.echo(f"{head} wrote: " + ", ".join(r.outputs.values()))
    click.echo(f"{head} waiting for the next save of the controller (Ctrl-C ends)")


def watch_drive(params: dict[str, Any]) -> None:
    """Run ``drive --watch`` with the drive command's parsed ``params``; exits."""
    from simrunner.cli import input_errors
    from simrunner.run.watch import watch_runs

    options = {k: v for k, v in params.items() if k != "watch"}
    controller = options.pop("controller")
    try:
        for event in watch_runs(controller, **options):
            _report(event)
            sys.stdout.flush()
    except input_errors() as exc:
        click.echo(f"simrunner: {exc}", err=True)
        sys.exit(2)
    except KeyboardInterrupt:
        pass
    click.echo("watch ended")
    sys.exit(130)
