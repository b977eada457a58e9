"""``simrunner gap MEASURED.csv -o DIR``: name the effect the simulator misses (issue 4).

A thin click layer over :func:`simrunner.workflows.gap.report.run_gap` and ``write_outputs``
(docs/gap.md). Exit codes: 0 done (whether or not an effect was named); 2 bad input (one
line ``file:line: what was expected`` on stderr, no traceback, nothing written).
"""
from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

import click

from simrunner.workflows.gap.replay import WINDOW_S, WORKFLOW_DT_S


@contextlib.contextmanager
def _engine_stderr_silenced():
    """Yield a text stream on the real stderr while fd 2 goes to /dev/null: the physics
    engine's C++ warnings would otherwise garble the progress bar."""
    try:
        saved = os.dup(2)
    except OSError:  # no fd 2 (detached process): nothing to silence
        yield sys.stderr
        return
    stream = os.fdopen(os.dup(saved), "w", buffering=1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    sys.stderr.flush()
    os.dup2(devnull, 2)
    os.close(devnull)
    try:
        yield stream
    finally:
        stream.flush()
        os.dup2(saved, 2)
        os.close(saved)
        stream.close()


@click.command("gap")
@click.argument("measured", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              metavar="DIR", help="Output folder (report.json, car.toml, plots); written atomically.")
@click.option("--car", default=None, type=click.Path(dir_okay=False, path_type=Path), metavar="CAR.toml",
              help="Nominal car description (default: built-in car).")
@click.option("--jobs", default=2, show_default=True, type=click.IntRange(min=1),
              help="Worker processes for the per-effect fits (results do not depend on it).")
@click.option("--effects", default=None, metavar="NAME,NAME",
              help="Only these catalogue effects (default: all).")
@click.option("--dt", "dt_s", default=WORKFLOW_DT_S, show_default=True,
              type=click.FloatRange(min=0, max=0.02, min_open=True), metavar="SECONDS",
              help="Physics step of the replays.")
@click.option("--window", "window_s", default=WINDOW_S, show_default=True,
              type=click.FloatRange(min=0.5, max=30.0), metavar="SECONDS",
              help="Replay window: each restarts from the measured state.")
@click.option("--force", is_flag=True, help="Replace DIR if it exists.")
@click.option("--no-progress", is_flag=True, help="No progress bar.")
def gap(measured: Path, out_dir: Path, car: Path | None, jobs: int, effects: str | None, dt_s: float,
        window_s: float, force: bool, no_progress: bool) -> None:
    """Find where MEASURED (a run log CSV, docs/telemetry.md) and the simulator disagree, name the missing
    effect, add it to the car and show the gap shrink on held-out data."""
    from tqdm import tqdm

    from simrunner.errors import SimError
    from simrunner.run.log import read_log
    from simrunner.workflows.gap.fit import CANDIDATES
    from simrunner.workflows.gap.logs import check_measured
    from simrunner.workflows.gap.report import progress_total, run_gap, summary_text, write_outputs
    from vehicle.description import CarDescriptionError, load_car

    try:
        if out_dir.exists() and not force:
            raise SimError(f"{out_dir}: output folder exists (use --force to replace it)")
        names = None
        if effects is not None:
            names = [n.strip() for n in effects.split(",") if n.strip()]
            bad = [n for n in names if n not in CANDIDATES]
            if bad or not names:
                raise SimError(f"--effects {effects!r}: expected names among {', '.join(CANDIDATES)}")
        description = load_car(car)
        log = check_measured(read_log(measured))
        total = progress_total(len(names) if names is not None else len(CANDIDATES))
        with _engine_stderr_silenced() as err:
            bar = tqdm(total=total, file=err, disable=no_progress, desc="gap", unit="fit", leave=False)

            def tick(label: str) -> None:
                bar.set_postfix_str(label)
                bar.update(1)

            try:
                result = run_gap(log, description, jobs=jobs, effects=names, dt_s=dt_s, window_s=window_s,
                                 progress=tick)
            finally:
                bar.close()
        write_outputs(result, out_dir, force=force)
    except (SimError, CarDescriptionError) as exc:
        click.echo(f"simrunner gap: {exc}", err=True)
        sys.exit(2)
    click.echo(summary_text(result))
    click.echo(f"wrote {out_dir}/ (report.json, car.toml, gap_before_after.png, residuals_by_regime.png)")
