"""simrunner gap on many short runs of one car (issue 51 item 4): runs as short as one replay
window are pooled, each fitted or held out whole, and the report counts runs."""
from __future__ import annotations

import numpy as np
import pytest

from simrunner.telemetry.log import LogError, write_log
from simrunner.workflows.gap.logs import check_measured
from simrunner.workflows.gap.report import summary_text
from simrunner.workflows.gap.synth import make_measured_log
from simrunner.workflows.gap.workflow import run_gap


def step_runs(n: int, duration_s: float = 3.0):
    """``n`` short runs from rest (parts of the excitation plan's speed steps), motor lag hidden."""
    return [make_measured_log("motor_lag", value=0.3, rng=np.random.default_rng(100 + k), start_s=44.0 + 1.5 * k,
                              duration_s=duration_s)[0] for k in range(n)]


@pytest.fixture(scope="module")
def pooled():
    logs = step_runs(6)
    return logs, run_gap(logs, jobs=1, effects=["motor_lag", "command_latency", "throttle_deadband"])


def test_a_single_short_log_is_still_refused_but_one_of_several_is_not():
    log = step_runs(1)[0]
    with pytest.raises(LogError, match=r"expected at least 50 rows and 6 s of data"):
        check_measured(log)
    assert check_measured(log, pooled=True) is log
    tiny = step_runs(1, duration_s=1.5)[0]
    with pytest.raises(LogError, match=r"expected at least 20 rows and 2 s of data"):
        check_measured(tiny, pooled=True)


def test_short_runs_are_fitted_or_held_out_whole(pooled):
    logs, result = pooled
    assert result.runs["runs"] == 6 and result.runs["held_out_whole"] == 2 and result.runs["fitted_whole"] == 4
    for part in result.parts:  # no run gives windows to both sets
        assert not (part.fit_windows and part.held_windows)
    assert "data: 6 runs (4 fitted whole, 2 held out whole)" in summary_text(result)


def test_pooled_short_runs_name_the_hidden_effect(pooled):
    _, result = pooled
    assert result.effects == ["motor_lag"]
    assert result.parameters["motor_lag_s"] == pytest.approx(0.3, rel=0.15)
    assert result.gap_after < 0.5 * result.gap_before


def test_the_cli_pools_short_files(tmp_path):
    from click.testing import CliRunner

    from simrunner.cli.gap import gap

    paths = []
    for k, log in enumerate(step_runs(3)):
        path = tmp_path / f"step{k}.csv"
        write_log(log, path)
        paths.append(str(path))
    res = CliRunner().invoke(gap, paths[:1] + ["-o", str(tmp_path / "one"), "--no-progress"])
    assert res.exit_code != 0 and "expected at least 50 rows and 6 s of data" in res.output
    res = CliRunner().invoke(gap, paths + ["-o", str(tmp_path / "out"), "--effects", "motor_lag", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert "data: 3 runs (2 fitted whole, 1 held out whole)" in res.output
