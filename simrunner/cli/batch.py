"""``simrunner batch``: a thin click layer over :func:`simrunner.workflows.batch.run_batch`."""
from __future__ import annotations

import sys

import click

from simrunner.cli import McuTime, build_options, end_without_teardown
from simrunner.cli.names import HELP
from simrunner.run.rules import EVENT_NAMES


@click.command("batch", context_settings=HELP)
@click.argument("controller", type=click.Path(dir_okay=False, path_type=str))
@click.argument("more_sources", nargs=-1, type=click.Path(dir_okay=False, path_type=str))
@click.option("--tracks", "tracks", multiple=True, metavar="SPEC",
              help="Tracks: layout/world files, folders, globs ('tracks/*.txt'), random:N, "
                   "'default' (the bundled track, the default); repeatable or comma-separated.")
@click.option("--seeds", default="1", show_default=True, metavar="N|A:B",
              help="Seeds of the camera noise: N = 0..N-1, A:B = A..B-1.")
@click.option("--param", "params", multiple=True, metavar="NAME=V1,V2|START:STOP:STEP",
              help="Controller parameter values to sweep (every combination); repeatable.")
@click.option("--laps", default=1, show_default=True, type=click.IntRange(min=1))
@click.option("--time-limit", "time_limit_s", default=None,
              type=click.FloatRange(min=0, min_open=True), metavar="SECONDS",
              help="Simulated-time limit of each run [default: as simrunner drive: max(60, "
                   "laps x lap length / 0.5 m/s); the race: 120].")
@click.option("--off-track-wheels", "off_track_wheels", default=None,
              type=click.IntRange(1, 4), metavar="N",
              help="Wheels off the road that end a run [default: 3, the rules' race; the event's].")
@click.option("--event", default=None, type=click.Choice(EVENT_NAMES),
              help="Run each as the rules' discipline (as simrunner drive --event).")
@click.option("--workers", default=None, type=click.IntRange(min=1),
              help="Worker processes (default: all cores; with --ray: the cluster's CPUs).")
@click.option("-o", "--out", "out_dir", required=True, metavar="DIR",
              help="Output folder: results.csv, results.json, summary.png, runs/.")
@click.option("--force", is_flag=True, help="Replace the results of an earlier batch in DIR.")
@click.option("--video", default="none", show_default=True, metavar="none|all|failures|N,M",
              help="Debug videos (DIR/runs/run_NNNNN.mp4) for these runs.")
@click.option("--csv", default="none", show_default=True, metavar="none|all|failures|N,M",
              help="Run-log CSVs (DIR/runs/run_NNNNN.csv) for these runs.")
@click.option("--run-timeout", "run_timeout_s", default=None, type=float, metavar="SECONDS",
              help="Wall-clock limit of one run (default 60 + 4 x its time limit).")
@click.option("--car", default=None, metavar="CAR.toml", help="Car description (default: built-in car).")
@click.option("--dt", "dt_s", default=0.002, show_default=True,
              type=click.FloatRange(min=0, max=0.02, min_open=True), metavar="SECONDS")
@click.option("--wall-limit", "wall_limit_s", default=10.0, show_default=True,
              type=click.FloatRange(min=0, min_open=True), metavar="SECONDS",
              help="Stop a run whose controller lets no simulated time pass for this long.")
@click.option("--ray", "ray", is_flag=False, flag_value="local", default=None, metavar="[ADDRESS]",
              help="Run on Ray: a local cluster without ADDRESS, else ray://host:10001 or "
                   "host:6379 (pip install 'nxpcup-sim[ray]').")
@click.option("--no-plot", is_flag=True, help="Do not write summary.png.")
@click.option("--mcu-time", "mcu_time", default=None, type=McuTime(), metavar="measured|SECONDS",
              help="The controller's own processing costs simulated time (as simrunner drive "
                   "--mcu-time; measured is not deterministic).")
@click.option("--mcu-scale", "mcu_scale", default=1.0, show_default=True,
              type=click.FloatRange(min=0, max=1e4, min_open=True), metavar="FACTOR",
              help="With --mcu-time measured: how many times slower the car's MCU runs the code.")
@build_options
def batch_cmd(controller, more_sources, tracks, seeds, params, laps, time_limit_s, workers, out_dir, force,
              video, csv, run_timeout_s, car, dt_s, wall_limit_s, ray, no_plot,
              off_track_wheels=None, event=None, mcu_time=None, mcu_scale=1.0, include_dirs=(),
              defines=(), kit=None, isrs=()) -> None:
    """Run CONTROLLER over tracks x parameters x seeds on all cores (or Ray); one row per run.
    C/C++ firmware: its sources and the options that build it, as for drive."""
    from simrunner.cli import _isr, input_errors
    from simrunner.workflows.batch import run_batch

    bar = _progress_bar()
    failed = [0]

    def on_row(row: dict) -> None:
        if row["outcome"] not in ("finished", "controller_returned"):
            failed[0] += 1
        bar.update(1)
        bar.set_postfix(failed=failed[0], refresh=False)

    import signal

    stopped_by: list[int] = []

    def stop(signum, frame):  # SIGTERM (timeout, CI, job schedulers), SIGHUP: as Ctrl-C
        stopped_by.append(signum)
        raise KeyboardInterrupt

    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        build = dict(sources=more_sources, include_dirs=include_dirs, defines=defines, kit=kit,
                     isrs=tuple(_isr(text) for text in isrs))
        result = run_batch(controller, out_dir=out_dir, tracks=tracks, seeds=seeds, params=params,
                           laps=laps, time_limit_s=time_limit_s, dt_s=dt_s,
                           wall_limit_s=wall_limit_s, car=car, workers=workers,
                           run_timeout_s=run_timeout_s, video=video, csv=csv, plot=not no_plot,
                           ray=ray, force=force, on_row=on_row, off_track_wheels=off_track_wheels,
                           event=event, mcu_time=mcu_time, mcu_scale=mcu_scale, build=build,
                           on_plan=lambda n: bar.reset(total=n))
    except input_errors() as exc:
        bar.close()
        lines = str(exc).splitlines() or [""]
        if len(lines) > 1 and lines[0].endswith(" failed:"):  # a compile error: the compiler's words
            lines = lines[:1] + [line for line in lines[1:] if line.strip()][:4]
            hint = getattr(exc, "hint", None)  # the simulator's own last line: what to do
            if hint and hint not in lines:
                lines.append(hint)
        else:
            lines = lines[:1]
        click.echo("simrunner batch: " + "\n".join(lines), err=True)
        sys.exit(2)
    except KeyboardInterrupt:
        bar.close()
        what = signal.Signals(stopped_by[0]).name if stopped_by else "interrupted"
        click.echo(f"simrunner batch: {what}; the finished runs are in {out_dir}/results.csv",
                   err=True)
        sys.exit(128 + (stopped_by[0] if stopped_by else signal.SIGINT))
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    bar.close()
    counts = ", ".join(f"{k} {v}" for k, v in sorted(result.counts().items()))
    laps_done = sum(r["laps_completed"] for r in result.rows)
    click.echo(f"{len(result.rows)} runs on {result.workers} worker(s) ({result.backend}) in "
               f"{result.wall_time_s:.1f} s: {counts}; {laps_done} laps")
    if result.unused_params:
        from simrunner.run.params import unused_params_text

        click.echo("simrunner batch: warning: " + unused_params_text(result.unused_params, result.params_read)
                   + ": its values changed nothing", err=True)
    for text, runs in result.warnings[:WARNINGS_SHOWN]:
        which = "every run" if len(runs) == len(result.rows) else f"{len(runs)} of {len(result.rows)} runs"
        click.echo(f"simrunner batch: warning ({which}): {text}", err=True)
    if len(result.warnings) > WARNINGS_SHOWN:
        click.echo(f"simrunner batch: {len(result.warnings) - WARNINGS_SHOWN} more warnings of the runs in "
                   f"{result.json_path} (\"warnings\")", err=True)
    if result.rerun_mismatches:
        click.echo("simrunner batch: warning: re-runs for outputs differed from the first run: "
                   + ", ".join(map(str, result.rerun_mismatches)), err=True)
    written = [result.csv_path, result.json_path] + ([result.plot_path] if result.plot_path else [])
    click.echo("wrote: " + ", ".join(map(str, written)))
    if ray is None:  # (Ray's driver keeps its connection and threads: the usual end)
        end_without_teardown(click.get_current_context())


WARNINGS_SHOWN = 5
"""Distinct warnings of the runs printed after a batch (all are in results.json)."""


class _NoBar:
    """The progress bar where none is shown: what a disabled ``tqdm`` does, nothing."""

    def update(self, n: int = 1) -> None:
        pass

    def set_postfix(self, **kw) -> None:
        pass

    def reset(self, total=None) -> None:
        pass

    def close(self) -> None:
        pass


def _progress_bar():
    """A ``tqdm`` bar on stderr when it is a terminal; else :class:`_NoBar` - what
    ``tqdm(disable=None)`` shows there (nothing), without importing tqdm (~20 ms: its version
    look-up reads the installed packages' metadata), as in scripts, CI and the bench."""
    if hasattr(sys.stderr, "isatty") and not sys.stderr.isatty():
        return _NoBar()
    from tqdm import tqdm

    tqdm.monitor_interval = 0  # no monitor thread: workers fork from this process (pool.py)
    return tqdm(total=None, unit="run", dynamic_ncols=True, file=sys.stderr, disable=None)
