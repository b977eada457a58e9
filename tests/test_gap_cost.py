"""What a gap run will cost, said or refused before the work (issue 50: a 200 MB log kept
``simrunner gap`` at 0 fits for 10 minutes at 2.3 GB)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.errors import SimError
from simrunner.telemetry.log import read_log
from simrunner.workflows.gap.cost import count_rows, estimate, span_s
from simrunner.workflows.gap.settings import SETTINGS


def _straight_log(path, duration_s: float = 20.0):
    """A car driving straight at 1 m/s, 50 Hz: a log ``check_measured`` takes."""
    t = np.arange(0.0, duration_s, 0.02)
    rows = "\n".join(f"{ti:.6f},{ti:.6f},0.000000,0.000000,1.000000,1.000000,0.000000" for ti in t)
    path.write_text("# nxpcup-sim run log, format 2\n\nt_s,x_m,y_m,yaw_rad,speed_mps,speed_cmd_mps,steer_cmd_rad\n"
                    + rows + "\n")
    return path


def test_rows_and_span_counted_without_reading_are_the_readers(tmp_path):
    path = _straight_log(tmp_path / "log.csv")
    log = read_log(path)
    assert count_rows(path) == len(log.t_s) == 1000
    assert span_s(path) == pytest.approx(log.t_s[-1] - log.t_s[0])
    assert math.isnan(span_s(tmp_path / "missing.csv"))


def test_span_of_a_format1_log_is_counted_as_the_reader_reads_it(tmp_path):
    """A log whose header names ``t`` (format 1, as the shared F1/10 logs): the reader takes it,
    so the refusal's cost gives its seconds of data too."""
    path = tmp_path / "f1.csv"
    t = np.arange(0.0, 20.0, 0.02)
    path.write_text("t,x,y,yaw,speed,speed_cmd,steer_cmd\n"
                    + "".join(f"{ti:.6f},{ti:.6f},0,0,1,1,0\n" for ti in t))
    log = read_log(path)
    assert span_s(path) == pytest.approx(log.t_s[-1] - log.t_s[0])
    r = CliRunner().invoke(cli, ["gap", str(path), "-o", str(tmp_path / "out"), "--max-rows", "600"])
    assert r.exit_code == 2 and "1,000 rows, 20 s of data: ~0.2 GB, ~" in r.output
    # the part it suggests (one header line here) holds --max-rows rows: gap takes it
    assert f"(head -n 601 {path} > part.csv)" in r.output
    part = tmp_path / "part.csv"
    part.write_text("".join(path.read_text().splitlines(keepends=True)[:601]))
    assert count_rows(part) == 600


def test_estimates_grow_with_the_log_and_the_chain_and_a_short_run_says_nothing():
    from simrunner.cli.gap import SAY_COST_MIN

    focused = estimate(4722, 94.4, n_effects=2)  # the synthetic logs of the tests and the bench, two effects
    hour = estimate(180_000, 3600.0)
    assert focused.minutes < SAY_COST_MIN <= hour.minutes
    assert focused.memory_mb < hour.memory_mb < estimate(3_000_000, 60_000.0).memory_mb
    # a chain of every candidate: ~2 min to its first step, and each later step longer (the kept
    # effects join its refits) - DS2's chain to step 5 took 19 min, DS3's to step 4 9.2 min
    whole = estimate(4722, 94.4)
    assert whole.steps == 7 and 1.0 < whole.first_minutes < 3.0 and 15.0 < whole.minutes < 30.0
    shorter = estimate(4722, 94.4, settings=dataclasses.replace(SETTINGS, max_effects=3))
    assert shorter.steps == 4 and shorter.first_minutes == whole.first_minutes and shorter.minutes < whole.minutes
    assert whole.text() == ("4,722 rows, 94 s of data: ~0.2 GB, ~2 min to the first step, up to ~20 min for a "
                            "chain of 7 steps")
    # the 200 MB log (~3 million rows, 16.5 h at 50 Hz): an hour or more, 2.5 GB
    big = estimate(3_000_000, 60_000.0)
    assert 30 < big.minutes < 120 and 2000 < big.memory_mb < 3000
    assert big.text() == ("3,000,000 rows, 60,000 s of data: ~2.5 GB, ~22 min to the first step, up to ~77 min "
                          "for a chain of 7 steps")


def test_a_log_past_max_rows_is_refused_before_reading_in_one_line(tmp_path):
    path = _straight_log(tmp_path / "long.csv")
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, ["gap", str(path), "-o", str(out), "--max-rows", "600"])
    assert r.exit_code == 2 and len(r.output.splitlines()) == 1
    assert r.output.startswith(f"simrunner gap: {path} (0 MB): 1,000 rows, 20 s of data: ~0.2 GB, ~")
    assert r.output.endswith(f"more than --max-rows 600: give gap a part (head -n 603 {path} > part.csv) "
                             "or raise --max-rows\n")
    assert not out.exists()


def test_a_long_run_says_its_cost_with_its_first_finding(tmp_path, monkeypatch, capfd):
    """Said with the first finding (on the terminal's stderr, as the findings), after the logs'
    own checks: a log refused at once is one line (tests/test_gap.py's car at rest)."""
    import simrunner.cli.gap as gap_cli
    import simrunner.workflows.gap.workflow as workflow

    def stop(*args, findings, **kwargs):
        findings.add("log", "the log, read")
        raise SimError("stopped here")

    monkeypatch.setattr(gap_cli, "SAY_COST_MIN", 0.0)
    monkeypatch.setattr(workflow, "run_gap", stop)
    path = _straight_log(tmp_path / "log.csv")
    r = CliRunner().invoke(cli, ["gap", str(path), "-o", str(tmp_path / "out"), "--no-progress"])
    assert r.exit_code == 2 and r.output.splitlines()[-1] == "simrunner gap: stopped here"
    said = capfd.readouterr().err.splitlines()
    assert said[0].startswith("simrunner gap: 1,000 rows, 20 s of data: ~0.2 GB, ~") and said[0].endswith(
        " min to the first step, up to ~7 min for a chain of 7 steps (estimated; docs/gap.md, --max-rows)")
    assert said[1].endswith("the log, read") and len(said) == 2
