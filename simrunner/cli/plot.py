"""``simrunner plot``: the run plot of any log (telemetry of ``drive --csv`` or a real car's
log read through a column mapping), a thin layer over :func:`simrunner.reports.plot.plot_run`."""
from __future__ import annotations

import sys
from pathlib import Path

import click

from simrunner.cli.names import HELP


@click.command("plot", context_settings=HELP)
@click.argument("log", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--out", default=None, type=click.Path(dir_okay=False, path_type=Path),
              metavar="PNG", help="Where to write the plot (default: LOG with .png).")
@click.option("--track", default=None, metavar="LAYOUT|DIR|WORLD",
              help="Draw the path over this track (layout .txt, trackgen folder, world, model folder).")
@click.option("--car", default=None, type=click.Path(dir_okay=False, path_type=Path), metavar="CAR.toml",
              help="Car description the track is checked against (default: built-in car).")
@click.option("--columns", "columns_file", default=None, type=click.Path(dir_okay=False, path_type=Path),
              metavar="MAP.toml", help="Column mapping for a log with other column names or units.")
@click.option("--column", "column_items", multiple=True, metavar="NAME=EXPR",
              help="One column rule, e.g. speed_mps=v/3.6 (repeatable; after --columns).")
def plot_cmd(log: Path, out: Path | None, track: str | None, car: Path | None,
             columns_file: Path | None, column_items: tuple[str, ...]) -> None:
    """Plot a run LOG (CSV): path, speed, steering, yaw rate, commands vs actual, laps, off track."""
    from simrunner.cli import input_errors
    from simrunner.telemetry.log import read_log
    from simrunner.reports.plot import log_title, plot_run

    out = out if out is not None else log.with_suffix(".png")
    try:
        mapping = None
        if columns_file is not None or column_items:
            from simrunner.telemetry.columns import column_map_from

            mapping = column_map_from(columns_file, column_items)
        run_log = read_log(log, columns=mapping)
        sim_track = None
        if track is not None:
            from simrunner.run.runner import resolve_track
            from vehicle.description import load_car

            sim_track, _ = resolve_track(track, load_car(car))
        written = plot_run(run_log, sim_track, out, title=log_title(run_log))
    except input_errors() as exc:
        click.echo(f"simrunner: {exc}", err=True)
        sys.exit(2)
    click.echo(f"wrote: {written}")
