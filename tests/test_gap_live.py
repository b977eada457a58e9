"""simrunner gap while it runs (issue 50 item 4): the findings as they come (to the terminal
and DIR/findings.txt), a partial report when the run is stopped, and ``--budget`` ending the
chain in time with the model of its finished steps."""
from __future__ import annotations

import functools
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from helpers import kill_alone_and_wait_for_its_session, kill_session, session_processes

from simrunner.telemetry.log import write_log
from simrunner.workflows.gap.live import Budget, Findings, uncertainty_replays
from simrunner.workflows.gap.synth import make_measured_log
from simrunner.workflows.gap.uncertainty import _stencil
from simrunner.workflows.gap.workflow import run_gap

EFFECTS = ["motor_lag", "speed_scale", "throttle_deadband"]


@functools.lru_cache(maxsize=1)
def lag_log():
    """The plan's speed steps with a motor lag hidden: a step that keeps it, one that keeps nothing
    (simulated once; a RunLog's columns are read-only)."""
    log, _ = make_measured_log("motor_lag", value=0.3, rng=np.random.default_rng(5), start_s=44.0, duration_s=16.0)
    return log


@pytest.fixture(scope="module")
def live_run():
    """The run, its findings, and every finding, fit batch and progress tick in order."""
    from simrunner.workflows.gap import chain

    found, events = [], []
    findings = Findings(lambda f: (found.append(f), events.append(("stage", f.data["fits"])) if f.kind == "stage"
                                   else None))
    run = chain._ChainBuilder.run
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(chain._ChainBuilder, "run", lambda self, jobs: (events.append(("run", len(jobs))), run(self, jobs))[1])
        result = run_gap(lag_log(), jobs=1, effects=EFFECTS, findings=findings,
                         progress=lambda label: events.append(("tick", label)))
    return result, findings, found, events


def test_findings_come_in_order_with_the_results_figures(live_run):
    result, findings, found, _ = live_run
    assert found == findings.items  # the listener saw each as it was made
    kinds = [f.kind for f in found if f.kind != "stage"]
    assert kinds[:2] == ["log", "nominal"] and kinds[-2:] == ["chain", "done"]
    assert [f.data["kept"] for f in findings.of_kind("step") if f.data["kept"]] == result.effects == ["motor_lag"]
    nominal, = findings.of_kind("nominal")
    assert nominal.data["held_gap"] == pytest.approx(result.gap_before, rel=1e-12)
    assert "16.0 s, " in found[0].text and "no glitch" in found[0].text
    last = findings.of_kind("step")[-1]
    assert last.text.endswith("no remaining effect passes the tests")
    assert findings.parameters == result.parameters and findings.effects == result.effects
    times = [f.elapsed_s for f in found]
    assert times == sorted(times)
    stages = [f for f in found if f.kind == "stage"]
    assert stages[0].text == "replaying the nominal car"
    screening = [f for f in stages if "screening" in f.text]
    assert [f.data["fits"] for f in screening][:2] == [3, 2]  # the effects left to screen at each step
    # each screening's ranking is a finding as it ends (a run stopped in the refits after it keeps it)
    screened = findings.of_kind("screened")
    assert [len(f.data["ranking"]) for f in screened] == [f.data["fits"] for f in screening]
    assert screened[0].text.startswith("step 1: screened 3 effects; the best alone: motor_lag (")


def test_no_fit_runs_while_the_progress_bar_is_full(live_run):
    """The bar counts the fits of the stage running: a fit batch after the stage's last tick
    left it at 100 % meanwhile (a kept candidate's second refit: ~12 s on a real log)."""
    *_, events = live_run
    fits = ticks = 0
    for kind, value in events:
        if kind == "stage":
            fits, ticks = value, 0
        elif kind == "tick":
            ticks += 1
        else:
            assert ticks < fits, f"a fit batch of {value} after the stage's {fits} tick(s): {events}"


def test_the_uncertainty_replays_are_counted_as_its_stencil():
    for k in range(1, 6):
        assert uncertainty_replays(k) == len(_stencil(np.full(k, 0.5), 0.01)) + 4 * k


def test_a_budget_keeps_the_closing_stages_time():
    now = [0.0]
    b = Budget(100.0, clock=lambda: now[0])
    b.measure(replay_s=1.0, closing_s=2.0, jobs=2)
    assert b.reserve_s(0) == pytest.approx(1.5 * 2.0)
    # one parameter: 3 stencil replays and 2 at half the step (twice the cost): 7 on 2 workers, 4 rounds
    assert b.reserve_s(1) == pytest.approx(1.5 * (4 * 1.0 + 2.0))
    now[0] = 100.0 - b.reserve_s(2) - 0.01
    assert not b.spent(2) and b.spent(3)
    b.tick()  # a fit took this long since measure(): the next may too
    assert b.wait_s() == pytest.approx(now[0]) and b.spent(2)
    with pytest.raises(Exception, match="expected a positive time"):
        Budget(0.0)


def test_a_budget_ends_the_chain_with_the_finished_steps(live_run):
    """The clock jumps to the end of the budget as the second step's screening runs: the result
    is the first step's model, confirmed and reported as stopped by the budget."""
    full, *_ = live_run
    now = [0.0]
    budget = Budget(3600.0, clock=lambda: now[0])

    def progress(label: str) -> None:
        if label.startswith("step 2"):
            now[0] = 3600.0

    findings = Findings()
    result = run_gap(lag_log(), jobs=1, effects=EFFECTS, findings=findings, budget=budget,
                     progress=progress)
    assert result.effects == ["motor_lag"] == full.effects[:1]
    assert result.chain.stop_reason.startswith("the time budget (60 min) ran out during step 2: screening")
    assert len(result.chain.steps) == 1  # the unfinished step is not in the chain
    assert result.gap_after < result.gap_before
    assert any(f.text.startswith("stopped: the time budget") for f in findings.items)
    assert math_close(result.parameters["motor_lag_s"], full.chain.steps[0].kept.parameters["motor_lag_s"])


def math_close(a: float, b: float) -> bool:
    return abs(a - b) <= 1e-9 * max(abs(a), abs(b), 1.0)


def test_a_spent_budget_tries_nothing():
    result = run_gap(lag_log(), jobs=1, effects=EFFECTS, budget=Budget(1e-6))
    assert result.effects == [] and result.chain.steps == ()
    assert "the time budget" in result.chain.stop_reason


def test_a_partial_report_lists_every_glitch_found(tmp_path):
    """The log finding names its first three glitches; a stopped run's report.json and
    residuals.txt keep all of them, as a whole report does (here: 5 gaps cut into the log)."""
    from simrunner.telemetry.log import read_log
    from simrunner.workflows.gap.report import partial_json, partial_text

    path = tmp_path / "m.csv"
    write_log(lag_log(), path)
    lines = path.read_text().splitlines(keepends=True)
    top = next(i for i, line in enumerate(lines) if line.startswith("t_s,")) + 1
    cut = {top + 60 * k + j for k in range(1, 6) for j in range(20)}  # 5 gaps of 20 rows (0.4 s)
    path.write_text("".join(line for i, line in enumerate(lines) if i not in cut))
    findings = Findings()
    run_gap(read_log(path), jobs=1, effects=EFFECTS, findings=findings, budget=Budget(1e-6))
    (log_finding,) = findings.of_kind("log")
    assert "5 glitches kept out" in log_finding.text and "and 2 more" in log_finding.text
    report = partial_json(findings, "stopped by SIGTERM")
    assert [g["kind"] for g in report["glitches"]] == ["time_gap"] * 5
    assert all(g["log"] == str(path) for g in report["glitches"])
    assert "glitch_list" not in report["findings"][0]
    json.dumps(report)
    text = partial_text(findings, "stopped by SIGTERM")
    assert "glitches kept out of the windows (5):" in text and text.count(": time_gap (t_s)") == 5


def _wait_for(path, text: str, proc, timeout_s: float) -> str:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        body = path.read_text() if path.exists() else ""
        if text in body:
            return body
        if proc.poll() is not None:
            break
        time.sleep(0.2)
    proc.kill()
    raise AssertionError(f"{text!r} not in {path} after {timeout_s} s (exit {proc.poll()})")


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_stopped_run_leaves_a_partial_report(tmp_path, signum):
    log_path = tmp_path / "m.csv"
    write_log(lag_log(), log_path)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-c", "from simrunner.cli import main; main()", "gap", str(log_path), "-o", str(out), "--jobs", "2",
                             "--effects", ",".join(EFFECTS), "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(out / "findings.txt", "step 1: kept motor_lag", proc, 240.0)
        proc.send_signal(signum)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signum, stderr
    assert "Traceback" not in stderr and "partial report in" in stderr
    assert "step 1: kept motor_lag" in stderr  # the findings reached the terminal as they came
    report = json.loads((out / "report.json").read_text())
    assert report["status"] == "partial" and report["effects"][:1] == ["motor_lag"]
    assert report["stopped"] == f"stopped by {'Ctrl-C (SIGINT)' if signum == signal.SIGINT else 'SIGTERM'}"
    assert "motor_lag_s" in (out / "car.toml").read_text()
    text = (out / "residuals.txt").read_text()
    assert text.startswith("PARTIAL REPORT: stopped by") and "motor_lag" in text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.csv", "out"]  # no temporary folder left
    _no_worker_left(proc.pid)


def _no_worker_left(pid: int) -> None:
    """No process of the stopped run is left (its fit workers were ended)."""
    left = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    if int(fh.read().rsplit(")", 1)[1].split()[1]) == pid:
                        left.append(int(entry))
            except OSError:
                continue
    assert not left


def test_findings_txt_is_in_a_finished_folder(tmp_path):
    from click.testing import CliRunner

    from simrunner.cli.gap import gap

    log_path = tmp_path / "m.csv"
    write_log(lag_log(), log_path)
    res = CliRunner().invoke(gap, [str(log_path), "-o", str(tmp_path / "out"), "--max-effects", "0", "--no-progress"])
    assert res.exit_code == 0, res.output
    lines = (tmp_path / "out" / "findings.txt").read_text().splitlines()
    assert lines[0].startswith("[0:0") and "m.csv: 16.0 s" in lines[0]
    assert "nominal car: held-out gap" in lines[1] and lines[-1].split("] ", 1)[1].startswith("done: effects none")


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")  # (the swallowed stop)
def test_a_stop_swallowed_where_it_landed_still_stops_the_run(tmp_path, monkeypatch, capfd):
    """The signal's handler ends the fit workers and raises where the main thread is; in a
    finalizer that exception is ignored, and the next fit finds the pool broken: the run is
    still the stop it is (exit 143, its message), not a BrokenProcessPool traceback."""
    from concurrent.futures.process import BrokenProcessPool

    from click.testing import CliRunner

    import simrunner.workflows.gap.workflow as workflow
    from simrunner.cli import main

    class Finalized:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGTERM)  # its handler's exception is ignored here

    def stopped_run(*args, **kwargs):
        Finalized()
        time.sleep(0.05)
        raise BrokenProcessPool("A child process terminated abruptly")

    monkeypatch.setattr(workflow, "run_gap", stopped_run)
    log_path = tmp_path / "m.csv"
    write_log(lag_log(), log_path)
    result = CliRunner().invoke(main, ["gap", str(log_path), "-o", str(tmp_path / "out"), "--no-progress"])
    err = capfd.readouterr().err
    assert result.exit_code == 128 + signal.SIGTERM, (result.output, err)
    assert "stopped by SIGTERM" in err and "Traceback" not in err + result.output


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="reads /proc")
def test_the_fit_workers_of_a_run_killed_alone_end_with_it(tmp_path):
    """kill -9 of gap's process alone (the out-of-memory killer, `timeout -s KILL`) left its fit
    workers finishing their fits, then waiting for work for ever."""
    log_path = tmp_path / "m.csv"
    write_log(lag_log(), log_path)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-c", "from simrunner.cli import main; main()", "gap", str(log_path),
                             "-o", str(out), "--jobs", "2", "--effects", ",".join(EFFECTS), "--no-progress"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        _wait_for(out / "findings.txt", "nominal car", proc, 240.0)
        end = time.monotonic() + 60
        while len(session_processes(proc.pid)) < 3 and time.monotonic() < end:  # gap and its 2 workers
            time.sleep(0.05)
        assert len(session_processes(proc.pid)) >= 3
        assert kill_alone_and_wait_for_its_session(proc) == []  # its process only, not its group
    finally:
        kill_session(proc)  # what is left of it
