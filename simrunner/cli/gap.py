"""``simrunner gap LOG.csv [LOG.csv ...] -o DIR``: the chain of effects the simulator misses.

A thin click layer over :func:`simrunner.workflows.gap.workflow.run_gap` and ``report.write_outputs``
(docs/gap.md). The findings are printed as they come (stderr) and appended to
``DIR/findings.txt``; the progress bar counts the fits of the stage running (its own total,
so its time estimate is the stage's). Exit codes: 0 done (whether or not effects were kept);
2 bad input (one line ``file:line: what was expected`` on stderr, no traceback, nothing
written); 130 stopped by Ctrl-C, 143 by SIGTERM, 129 by SIGHUP, with the partial report
(``report.write_partial``) in DIR.
"""
from __future__ import annotations

import contextlib
import dataclasses
import multiprocessing
import os
import signal
import sys
import threading
from pathlib import Path

import click

from simrunner.cli.names import HELP
from simrunner.workflows.gap.settings import SETTINGS


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


class _Stopped(KeyboardInterrupt):
    """Ctrl-C, SIGTERM or SIGHUP while the workflow runs."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)

    def words(self) -> str:
        return "Ctrl-C (SIGINT)" if self.signum == signal.SIGINT else signal.Signals(self.signum).name


@contextlib.contextmanager
def _stop_on_signals():
    """SIGINT, SIGTERM and SIGHUP raise :class:`_Stopped` in the main thread after ending the fit
    workers (whose running fits would otherwise be waited for); later ones are only noted (the
    partial report is being written). Yields the list of signals received."""
    received: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return

    def handler(signum, frame):
        received.append(signum)
        if len(received) > 1:
            return
        for child in multiprocessing.active_children():
            child.terminate()
        raise _Stopped(signum)

    sigs = [s for s in (signal.SIGINT, getattr(signal, "SIGTERM", None), getattr(signal, "SIGHUP", None)) if s]
    old = {s: signal.signal(s, handler) for s in sigs}
    try:
        yield received
    finally:
        for s, h in old.items():
            signal.signal(s, h)


class _LiveView:
    """The terminal while the workflow runs: each finding a line (stderr), the progress bar the
    fits of the stage running (reset per stage: its total and time estimate are the stage's)."""

    def __init__(self, stream, no_progress: bool, live, preface: str = ""):
        from tqdm import tqdm

        self.preface = preface  # said before the first finding: after the logs' own checks, so a
        # log refused at once is one line

        tqdm.monitor_interval = 0  # no monitor thread: it outlives the bar, and a batch run later in
        # this process would then start its workers cold (simrunner.workflows.batch.pool)
        self.stream, self.live = stream, live
        self.bar = tqdm(total=1, file=stream, disable=no_progress, desc="reading the logs", unit="fit", leave=False)

    def finding(self, f) -> None:
        if f.kind == "stage":
            self.bar.set_description_str(f.text, refresh=False)  # not drawn with the last stage's total
            self.bar.reset(total=max(int(f.data.get("fits", 1)), 1))
        else:
            if self.preface:
                self.bar.write(self.preface, file=self.stream)
                self.preface = ""
            self.bar.write(f.line(), file=self.stream)
        self.live.add(f)

    def tick(self, label: str) -> None:
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


@click.command("gap", context_settings=HELP)
@click.argument("measured", nargs=-1, required=True, type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              metavar="DIR", help="Output folder (report.json, car.toml, plots); written atomically.")
@click.option("--car", default=None, type=click.Path(dir_okay=False, path_type=Path), metavar="CAR.toml",
              help="Nominal car description (default: built-in car).")
@click.option("--columns", "columns_file", default=None, type=click.Path(dir_okay=False, path_type=Path),
              metavar="MAP.toml", help="Column mapping for logs with other column names or units "
                                       "(docs/telemetry.md).")
@click.option("--column", "column_items", multiple=True, metavar="NAME=EXPR",
              help="One column mapping item (repeatable; overrides --columns), e.g. "
                   "speed_cmd_mps='duty / 100 * 3.1'.")
@click.option("--norms", "norms_file", default=None, type=click.Path(dir_okay=False, path_type=Path),
              metavar="CONTROLLER.py", help="The Python controller whose spinner.configure(speed_norm=, "
                                            "turn_norm=) the mapping calls: speed_cmd_mps='speed_norm(duty, servo)'.")
@click.option("--jobs", default=2, show_default=True, type=click.IntRange(min=1),
              help="Worker processes for the fits (results do not depend on it).")
@click.option("--effects", default=None, metavar="NAME,NAME",
              help="Only these catalogue effects (default: all).")
@click.option("--max-effects", default=None, type=click.IntRange(min=0, max=50), metavar="N",
              help=f"Keep at most N effects (default: {SETTINGS.max_effects}).")
@click.option("--dt", "dt_s", default=None, type=click.FloatRange(min=0, max=0.02, min_open=True), metavar="SECONDS",
              help=f"Physics step of the replays (default: {SETTINGS.workflow_dt_s:g}).")
@click.option("--window", "window_s", default=None, type=click.FloatRange(min=0.5, max=30.0), metavar="SECONDS",
              help=f"Replay window: each restarts from the measured state (default: {SETTINGS.window_s:g}).")
@click.option("--screen", "screen_s", default=None, type=click.FloatRange(min=0.0),
              metavar="SECONDS", help="Seconds of fit windows the screening and refits use on a longer "
                                      "log, chosen by regime; 0: all of them (slower; a near tie then "
                                      f"depends less on the windows' layout; default: {SETTINGS.screen_max_s:g}).")
@click.option("--settings", "settings_file", default=None, type=click.Path(dir_okay=False, path_type=Path),
              metavar="FILE.toml", help="Thresholds to change, `name = value` (docs/gap.md \"Thresholds\"; "
                                        "the options above win).")
@click.option("--max-rows", default=None, type=click.IntRange(min=1), metavar="N",
              help="Refuse logs of more rows than this in all, before reading them (the time and memory "
                   f"grow with every row: docs/gap.md; default: {SETTINGS.max_rows}).")
@click.option("--budget", "budget_min", default=None, type=click.FloatRange(min=0, min_open=True),
              metavar="MINUTES", help="End within MINUTES: the chain stops in time, with the model of its "
                                      "finished steps (the report says so).")
@click.option("--force", is_flag=True, help="Replace DIR if it exists.")
@click.option("--no-progress", is_flag=True, help="No progress bar.")
def gap(measured: tuple[Path, ...], out_dir: Path, car: Path | None, columns_file: Path | None,
        column_items: tuple[str, ...], norms_file: Path | None, jobs: int, effects: str | None, max_effects: int | None,
        dt_s: float | None, window_s: float | None, screen_s: float | None, settings_file: Path | None,
        max_rows: int | None, budget_min: float | None, force: bool, no_progress: bool) -> None:
    """Find where MEASURED (one or several run logs of one car, docs/telemetry.md) and the
    simulator disagree, build the chain of effects that closes the gap, and show it shrink on
    held-out data.

    \b
    A log needs the commands and a pose or a speed sensor (a gyro helps); a log merged from
    several topics (a row per message, other cells empty) is read at its pose's (else its
    speed sensor's) samples. A column reversed or in another unit (a gyro in deg/s, steering
    + = right) is refused with the mapping that fixes it (docs/gap.md, "Input").

    \b
    The findings are printed as they come and kept in DIR/findings.txt; Ctrl-C or SIGTERM
    leaves a partial report in DIR (the model of the finished steps)."""
    from simrunner.cli import input_errors
    from simrunner.errors import SimError
    from simrunner.workflows.gap.cost import estimate
    from simrunner.workflows.gap.fit import CANDIDATES
    from simrunner.workflows.gap.logs import check_measured
    from simrunner.workflows.gap.live import Budget, Findings
    from simrunner.workflows.gap.report import LiveFolder, check_output_dir, summary_text, write_outputs
    from simrunner.workflows.gap.settings import load_settings
    from simrunner.workflows.gap.workflow import run_gap
    from vehicle.description import load_car

    try:
        check_output_dir(out_dir, force=force)
        names = None
        if effects is not None:
            names = [n.strip() for n in effects.split(",") if n.strip()]
            bad = [n for n in names if n not in CANDIDATES]
            if bad or not names:
                raise SimError(f"--effects {effects!r}: expected names among {', '.join(CANDIDATES)}")
        settings = load_settings(settings_file) if settings_file is not None else SETTINGS
        description = named_after_file(load_car(car), car)
        limit = settings.max_effects if max_effects is None else max_effects
        n_effects = len(names) if names is not None else len(CANDIDATES)
        shape = dataclasses.replace(settings, **{k: v for k, v in (("max_effects", limit), ("screen_max_s", screen_s),
                                                                   ("workflow_dt_s", dt_s)) if v is not None})
        refuse_large(measured, settings.max_rows if max_rows is None else max_rows, jobs=jobs, n_effects=n_effects,
                     settings=shape)
        read = _read_logs(measured, columns_file, column_items, norms_file)
        logs = [check_measured(log, pooled=len(read) > 1, settings=settings) for log in read]
        cost = estimate(sum(len(log.t_s) for log in logs), sum(float(log.t_s[-1] - log.t_s[0]) for log in logs),
                        jobs=jobs, n_effects=n_effects, settings=shape)
        say = f"simrunner gap: {cost.text()} (estimated; docs/gap.md, --max-rows)" if cost.minutes >= SAY_COST_MIN else ""
        live = LiveFolder(out_dir, force=force)
        with _engine_stderr_silenced() as err, _stop_on_signals() as received:
            view = _LiveView(err, no_progress, live, say)
            findings = Findings(view.finding)
            try:
                result = run_gap(logs, description, jobs=jobs, effects=names, settings=settings, dt_s=dt_s,
                                 window_s=window_s, max_effects=limit, screen_max_s=screen_s, progress=view.tick,
                                 findings=findings, budget=Budget(budget_min * 60.0) if budget_min else None)
            except _Stopped as stop:
                view.close()
                _write_stopped(findings, live, out_dir, stop, err)
            except Exception:
                # a signal whose _Stopped was swallowed where it landed (a finalizer ignores what
                # it raises): its ended workers then broke the fit pool - the stop, all the same
                if not received:
                    raise
                view.close()
                _write_stopped(findings, live, out_dir, _Stopped(received[0]), err)
            finally:
                view.close()
        try:
            write_outputs(result, out_dir, force=force or live.started, findings=findings)
        except input_errors():
            click.echo(summary_text(result))  # the run's answer is not lost with the folder
            raise
    except input_errors() as exc:
        click.echo(f"simrunner gap: {exc}", err=True)
        sys.exit(2)
    click.echo(summary_text(result))
    click.echo(f"wrote {out_dir}/ (report.json, car.toml, residuals.txt, findings.txt, gap_before_after.png, "
               f"residuals_by_regime.png)")


def _write_stopped(findings, live, out_dir: Path, stop: _Stopped, err) -> None:
    """A run stopped by a signal: its partial report (when its folder was started) and the exit
    status of the signal (130, 143, 129)."""
    from simrunner.workflows.gap.report import write_partial

    how = f"stopped by {stop.words()}"
    if live.started:
        write_partial(findings, out_dir, how)
        print(f"simrunner gap: {how} during {findings.stage}; partial report in {out_dir}/ (report.json "
              f"\"status\": \"partial\", the model of the finished steps in car.toml, findings.txt)", file=err)
    else:
        print(f"simrunner gap: {how} during {findings.stage}, before the nominal car's replay: nothing written",
              file=err)
    err.flush()
    sys.exit(128 + stop.signum)


SAY_COST_MIN = 5.0  # a run estimated to take longer says so (and what it reads) with its first finding


def refuse_large(paths: tuple[Path, ...], max_rows: int, **estimate_kw) -> None:
    """SimError (one line naming the largest file, the cost and the ways out) when ``paths``
    hold more than ``max_rows`` rows in all; counted before anything is read."""
    from simrunner.errors import SimError
    from simrunner.workflows.gap.cost import count_rows, estimate, head_lines, span_s

    rows = {}
    for path in paths:
        try:
            rows[path] = count_rows(path)
        except OSError:  # reading it says what is wrong
            continue
    if sum(rows.values()) <= max_rows:
        return
    big = max(rows, key=rows.get)
    spans = [span_s(p) for p in rows]
    cost = estimate(sum(rows.values()), sum(spans), **estimate_kw)
    logs = f" in {len(rows)} logs" if len(rows) > 1 else ""
    raise SimError(f"{big} ({big.stat().st_size / 1e6:.0f} MB): {cost.text()}{logs}, more than --max-rows "
                   f"{max_rows:,}: give gap a part (head -n {head_lines(big, min(max_rows, rows[big]))} {big} > part.csv) "
                   f"or raise --max-rows")


def named_after_file(description, path: Path | None):
    """The car of ``--car FILE`` named after FILE when the file sets no ``name`` (the gap's
    car.toml, derived from it, then carries FILE's name rather than the built-in car's)."""
    from vehicle.description import CarDescription

    if path is None or description.name != CarDescription().name:
        return description
    return description.replace(name=Path(path).stem)


def _read_logs(paths: tuple[Path, ...], columns_file: Path | None, items: tuple[str, ...],
               norms_file: Path | None = None) -> list:
    """The logs, read with the column mapping of ``--columns``/``--column`` (if any; its
    ``speed_norm``/``turn_norm`` those ``--norms`` configures), reading merged topic logs
    (empty cells: :mod:`simrunner.telemetry.sparse`) and leaving out a row that repeats the stamp
    before it (listed as a duplicate glitch). Several logs share the mapping, each with the
    sensors it has (``ColumnMap.partial``); a rule no log can follow is an error."""
    from simrunner.telemetry.log import read_log

    if columns_file is None and not items and norms_file is None:
        return [read_log(path, merged=True, repeated_stamps=True) for path in paths]
    from simrunner.telemetry.columns import column_map_from, read_mapped_logs

    norms = None
    if norms_file is not None:
        from simrunner.run.norms import controller_norms

        norms = controller_norms(norms_file)
    mapping = column_map_from(columns_file, items, norms, norms_from=f"--norms {norms_file}")
    return read_mapped_logs(paths, mapping, merged=True, repeated_stamps=True)
