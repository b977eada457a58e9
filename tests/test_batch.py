"""simrunner batch: job specs (tracks, seeds, value lists and ranges), rows bit-identical
for 1 and 2 workers, failing / crashing / hanging runs recorded without stopping the batch,
outputs for the failures, the CLI (one line, exit 2, for bad input)."""
from __future__ import annotations

import json
import signal
import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, strategies as st

from simrunner.cli import main as cli
from simrunner.run.runner import default_track
from simrunner.workflows.batch import BatchError, deterministic, read_results, run_batch
from simrunner.workflows.batch.results import columns
from simrunner.workflows.batch.spec import (make_jobs, parse_grid, parse_seeds, parse_values,
                                            resolve_tracks)

from helpers import FAULTY, kill_alone_and_wait_for_its_session, kill_session

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
FOLLOWER = EXAMPLES / "line_follower.py"




@pytest.mark.parametrize("text, values", [
    ("1.5,2,left", [1.5, 2, "left"]),
    ("1.0:2.0:0.5", [1.0, 1.5, 2.0]),
    ("0.1:0.3:0.1", [0.1, 0.2, 0.3]),
    ("1:5:2", [1, 3, 5]),
    ("1:2:0.3", [1.0, 1.3, 1.6, 1.9]),
    ("0:1:1,7", [0, 1, 7]),
    ("a:b:c", ["a:b:c"]),
])
def test_value_lists_and_ranges(text, values):
    got = parse_values(text)
    assert got == values and [type(v) for v in got] == [type(v) for v in values]


@given(start=st.decimals(-100, 100, places=2), n=st.integers(0, 40),
       step=st.decimals("0.01", 10, places=2))
def test_ranges_are_exact_decimals(start, n, step):
    stop = start + n * step
    got = parse_values(f"{start}:{stop}:{step}")
    assert len(got) == n + 1
    assert got == [float(start + i * step) for i in range(n + 1)] or all(isinstance(v, int) for v in got)


@pytest.mark.parametrize("text, match", [
    ("2:1:0.5", "START <= STOP"), ("1:2:0", "STEP > 0"), ("0:1e9:1", "at most"), ("1,,2", "empty"),
    ("1:2", r"'1:2': a range needs its step, START:STOP:STEP \(e.g. 1:2:0.5\)"),
])
def test_bad_value_lists(text, match):
    with pytest.raises(BatchError, match=match):
        parse_values(text)


def test_grid_seeds_and_job_order():
    grid = parse_grid(["v=1,2", "mode=a,b"])
    assert grid == {"v": [1, 2], "mode": ["a", "b"]}
    with pytest.raises(BatchError, match="results column"):
        parse_grid(["outcome=1"], reserved=tuple(columns(())))
    with pytest.raises(BatchError, match="given twice"):
        parse_grid(["v=1", "v=2"])
    with pytest.raises(BatchError, match="NAME=V1,V2"):
        parse_grid(["v"])
    assert parse_seeds(3) == [0, 1, 2] and parse_seeds("5:7") == [5, 6]
    for bad in ("0", "x", "3:3", "-1:2"):
        with pytest.raises(BatchError, match="--seeds"):
            parse_seeds(bad)
    tracks = resolve_tracks(["random:2"])
    jobs = make_jobs(tracks, [0, 1], grid)
    assert len(jobs) == 2 * 4 * 2 and [j.index for j in jobs] == list(range(16))
    assert (jobs[0].track.label, jobs[0].params, jobs[0].seed) == ("random:0", (("v", 1), ("mode", "a")), 0)
    assert (jobs[1].seed, jobs[2].params) == (1, (("v", 1), ("mode", "b")))


def test_track_specs(tmp_path):
    (tmp_path / "a.txt").write_text((EXAMPLES / "oval_start.txt").read_text())
    (tmp_path / "b.txt").write_text((EXAMPLES / "oval_start.txt").read_text())
    (tmp_path / "notes.md").write_text("x")
    labels = [r.label for r in resolve_tracks([str(tmp_path)])]
    assert labels == [str(tmp_path / "a.txt"), str(tmp_path / "b.txt")]
    assert [r.label for r in resolve_tracks([str(tmp_path / "*.txt") + ",random:1"])] == labels + ["random:0"]
    default = resolve_tracks(["default," + str(tmp_path / "a.txt")])[0]  # the bundled track by name
    assert default.label == "default" and default.path == str(default_track())
    for spec, match in ((str(tmp_path / "nope.txt"), "no such file"), (str(tmp_path / "*.sdf"), "matches no"),
                        (str(tmp_path / "notes.md"), "not a track"), ("random:0", "random:N"),
                        (str(tmp_path / "a.txt") + "," + str(tmp_path / "a.txt"), "given twice")):
        with pytest.raises(BatchError, match=match):
            resolve_tracks([spec])


def test_rows_identical_for_one_and_two_workers(tmp_path):
    common = dict(tracks=["random:1", str(EXAMPLES / "oval_start.txt")], seeds=2,
                  params=["v_max=2.0,2.8"], time_limit_s=3.0)
    one = run_batch(FOLLOWER, out_dir=tmp_path / "one", workers=1, **common)
    two = run_batch(FOLLOWER, out_dir=tmp_path / "two", workers=2, **common)
    assert len(one.rows) == 8 and [r["run"] for r in two.rows] == list(range(8))
    assert [deterministic(r) for r in one.rows] == [deterministic(r) for r in two.rows]
    assert len({r["sim_time_s"] for r in one.rows}) >= 1
    assert {r["v_max"] for r in one.rows} == {2.0, 2.8}
    # the files: CSV rows equal apart from the wall-clock columns; JSON rows read back
    strip = lambda p: [line.rsplit(",", 2)[0] for line in (p / "results.csv").read_text().splitlines()]  # noqa: E731
    assert strip(tmp_path / "one") == strip(tmp_path / "two")
    assert read_results(tmp_path / "two" / "results.json") == json.loads(json.dumps(two.rows))
    assert (tmp_path / "one" / "summary.png").stat().st_size > 10_000
    # every worker's timing (for benchmarks): ready before its first row, rows counted
    assert len(two.worker_timing) == 2 and sum(w.runs for w in two.worker_timing) == 8
    assert all(w.started_at <= w.ready_at <= w.first_row_at <= w.last_row_at for w in two.worker_timing)


def test_batch_mcu_time_charges_each_run(tmp_path):
    """--mcu-time in a batch: a fixed cost per Spinner call slows every run's lap, as in drive."""
    common = dict(seeds=1, workers=1, plot=False)
    plain = run_batch(FOLLOWER, out_dir=tmp_path / "plain", **common)
    slow = run_batch(FOLLOWER, out_dir=tmp_path / "slow", mcu_time=0.01, **common)
    assert slow.rows[0]["outcome"] == plain.rows[0]["outcome"] == "finished"
    assert slow.rows[0]["sim_time_s"] > plain.rows[0]["sim_time_s"]
    meta = json.loads((tmp_path / "slow" / "results.json").read_text())
    assert meta["mcu_time"] == 0.01 and meta["mcu_scale"] == 1.0
    with pytest.raises(Exception, match=r"mcu_time = 'soon'"):
        run_batch(FOLLOWER, out_dir=tmp_path / "bad", mcu_time="soon", **common)


def test_batch_event_race_rows_carry_the_result_and_penalty(tmp_path):
    res = CliRunner().invoke(cli, ["batch", str(FOLLOWER), "--tracks", str(EXAMPLES / "kit_S.txt"),
                                   "--seeds", "2", "--event", "race", "--workers", "1", "--no-plot",
                                   "-o", str(tmp_path / "race")])
    assert res.exit_code == 0, res.output
    rows = read_results(tmp_path / "race" / "results.json")
    assert [r["outcome"] for r in rows] == ["finished", "finished"] and all(r["passed"] for r in rows)
    # the follower never stops after the finish line: +1 s each
    assert all(r["penalty_s"] == 1.0 and r["time_s"] == pytest.approx(r["lap_times_s"][0] + 1.0) for r in rows)
    meta = json.loads((tmp_path / "race" / "results.json").read_text())
    assert meta["event"] == "race" and meta["time_limit_s"] == 120.0


def test_the_default_time_limit_is_drives(tmp_path):
    """Issue 50: batch ran 60 s where drive gives max(60 s, laps x lap length / 0.5 m/s).
    A car standing still for 3 laps of the bundled track (14.7 m): the same timeout in both."""
    from simrunner.run.runner import drive

    ctl = tmp_path / "still.py"
    ctl.write_text("def main(s):\n    while True:\n        s.sleep(10.0)\n")
    res = run_batch(ctl, out_dir=tmp_path / "out", laps=3, dt_s=0.02, workers=1, plot=False)
    alone = drive(ctl, laps=3, dt_s=0.02)
    row = res.rows[0]
    assert row["outcome"] == alone.outcome == "timeout" and row["message"] == alone.message
    assert row["sim_time_s"] == alone.sim_time_s > 88.0   # 3 x 14.74 m / 0.5 m/s, not 60 s
    assert json.loads((tmp_path / "out" / "results.json").read_text())["time_limit_s"] is None


def test_faulty_runs_never_stop_the_batch(tmp_path):
    ctl = tmp_path / "faulty.py"
    ctl.write_text(textwrap.dedent(FAULTY))
    res = run_batch(ctl, out_dir=tmp_path / "out", params=["mode=drive,crash,die,slow"],
                    time_limit_s=1000.0, workers=2, run_timeout_s=8.0, csv="failures",
                    tracks=[str(EXAMPLES / "oval_start.txt")])
    by_mode = {r["mode"]: r for r in res.rows}
    assert by_mode["drive"]["outcome"] == "off_track"
    assert by_mode["drive"]["off_x_m"] is not None and 0.0 <= by_mode["drive"]["off_progress_frac"] <= 1.0
    assert by_mode["crash"]["outcome"] == "controller_error" and "boom" in by_mode["crash"]["message"]
    assert by_mode["die"]["outcome"] == "worker_died", by_mode["die"]
    assert by_mode["slow"]["outcome"] == "wall_timeout"
    runs = sorted(p.name for p in (tmp_path / "out" / "runs").iterdir())
    # failures re-run with a CSV (crash and off-track; the dead and the hung runs again fail)
    assert "run_00000.csv" in runs and "run_00001.csv" in runs


def test_a_job_handed_to_a_dead_local_worker_is_reported_not_raised():
    """A job queued on a worker that has just died (the pipe is closed): handing it over
    does not raise; waiting reports the worker's death."""
    from simrunner.workflows.batch.pool import LocalBackend
    from simrunner.workflows.batch.spec import BatchConfig

    backend = LocalBackend(BatchConfig(controller=str(FOLLOWER)))
    try:
        h = backend.start()
        h.ref.process.kill()
        h.ref.process.join(timeout=30.0)
        job = make_jobs(resolve_tracks(["random:1"]), [0], {})[0]
        backend.submit(h, job, None)
        got = []
        for _ in range(60):   # each wait returns at once here: the worker's sentinel is ready
            got = backend.wait([h], 1.0)
            if got:
                break
        assert got and "died" in got[0][2]
        row = got[0][1]   # the row of the run it died in, naming the signal as drive does
        assert row["run"] == 0 and row["outcome"] == "worker_died"
        assert row["message"].startswith("the run's process was killed by SIGKILL (kill -9")
    finally:
        backend.close()


def test_cli_batch_and_bad_input(tmp_path):
    runner = CliRunner()
    out = tmp_path / "b"
    res = runner.invoke(cli, ["batch", str(FOLLOWER), "--tracks", "random:1", "--seeds", "1",
                              "--param", "v_max=2.0", "--time-limit", "2", "--workers", "1",
                              "-o", str(out), "--no-plot"])
    assert res.exit_code == 0, res.output
    assert "1 runs on 1 worker(s)" in res.output and (out / "results.csv").is_file()
    header = (out / "results.csv").read_text().splitlines()[0].split(",")
    assert header[:4] == ["run", "track", "seed", "v_max"] and header[-2:] == ["wall_time_s", "cpu_time_s"]
    res = runner.invoke(cli, ["batch", str(FOLLOWER), "--tracks", "random:1", "-o", str(out)])
    assert res.exit_code == 2 and "already holds results.csv" in res.output
    for args, match in ((["--tracks", str(tmp_path / "none.txt")], "no such file"),
                        (["--param", "v=2:1:1"], "START <= STOP"),
                        (["--video", "some"], "expected none, all, failures")):
        res = runner.invoke(cli, ["batch", str(FOLLOWER), "-o", str(tmp_path / "c"), *args])
        assert res.exit_code == 2 and match in res.output, res.output
        assert not (tmp_path / "c" / "results.csv").exists()
    res = runner.invoke(cli, ["batch", str(tmp_path / "missing.py"), "-o", str(tmp_path / "d")])
    assert res.exit_code == 2


def test_the_runs_warnings_are_the_batchs_once_each(tmp_path):
    """A run's warnings (a controller reading the computer's clock, say) reached drive's output
    and summary but no batch row: the batch said nothing. Each distinct warning is now in
    results.json with the runs that gave it, and printed once after the batch."""
    import json

    ctl = tmp_path / "clocky.py"
    ctl.write_text("import time\n\n\ndef main(spinner):\n    while True:\n"
                   "        spinner.get_image()\n        spinner.set_speed(0.5 + 0 * time.monotonic())\n")
    res = run_batch(ctl, out_dir=tmp_path / "a", seeds=3, workers=2, time_limit_s=0.5, plot=False)
    (text, runs), = res.warnings
    assert text.startswith(f"{ctl}:7: time.monotonic() reads the computer's clock") and runs == (0, 1, 2)
    assert json.loads(res.json_path.read_text())["warnings"] == [{"text": text, "runs": [0, 1, 2]}]
    out = CliRunner().invoke(cli, ["batch", str(ctl), "--seeds", "2", "--workers", "1", "--time-limit", "0.5",
                                   "--no-plot", "-o", str(tmp_path / "b")])
    assert out.exit_code == 0 and f"simrunner batch: warning (every run): {text}" in out.output
    quiet = run_batch(FOLLOWER, out_dir=tmp_path / "c", seeds=1, workers=1, time_limit_s=0.5, plot=False)
    assert quiet.warnings == ()


def test_the_program_ends_a_batch_without_the_interpreters_teardown(tmp_path):
    """``simrunner batch`` as a program (the entry point :func:`simrunner.cli.run`) ends with
    ``os._exit`` after its exit handlers and flushed output (~20 ms less): the status, the
    lines on a pipe and the files are as before and an atexit handler runs. A batch that
    fails ends as usual (``sys.exit``, the interpreter's teardown)."""
    import subprocess
    import sys

    probe = tmp_path / "probe.txt"
    code = ("import atexit, os, sys\n"
            "real_exit = os._exit\n"
            f"note = lambda text: open({str(probe)!r}, 'a').write(text)\n"
            "me = os.getpid()  # (the forked workers end by os._exit too)\n"
            "os._exit = lambda status: (os.getpid() == me and note(f'os._exit({status})'), real_exit(status))\n"
            "atexit.register(lambda: note('atexit, '))\n"
            "from simrunner.cli import run\n"
            "sys.argv[0] = 'simrunner'\n"
            "run()\n")
    out = tmp_path / "b"
    args = ["batch", str(FOLLOWER), "--seeds", "2", "--workers", "2", "--time-limit", "2", "--no-plot", "-o", str(out)]
    proc = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "2 runs on 2 worker(s)" in proc.stdout and f"wrote: {out / 'results.csv'}" in proc.stdout
    assert len((out / "results.csv").read_text().splitlines()) == 3
    assert probe.read_text() == "atexit, os._exit(0)"
    probe.unlink()
    proc = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and "already holds results.csv" in proc.stderr
    assert probe.read_text() == "atexit, "


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_a_stopped_batch_keeps_its_finished_runs(tmp_path, sig):
    """Issue 50 (fault injection): SIGTERM, SIGHUP or kill -9 lost every finished row. Rows now
    go to results.partial.csv as they finish; SIGTERM also writes results.csv (exit 143)."""
    import os
    import subprocess
    import sys
    import time

    out = tmp_path / "out"
    cmd = [str(Path(sys.executable).parent / "simrunner"), "batch", str(FOLLOWER), "--seeds", "20", "--workers", "1",
           "--time-limit", "2", "--no-plot", "-o", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
                            cwd=str(tmp_path))
    partial = out / "results.partial.csv"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if partial.exists() and len(partial.read_text().splitlines()) >= 3:  # header + 2 runs
                break
            time.sleep(0.1)
        assert proc.poll() is None, proc.communicate()
        os.killpg(proc.pid, sig) if sig == signal.SIGKILL else proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # orphaned workers of a killed batch
        except ProcessLookupError:
            pass
    if sig == signal.SIGTERM:
        assert proc.returncode == 143 and b"SIGTERM" in err
        rows = (out / "results.csv").read_text().splitlines()
        assert 3 <= len(rows) < 21 and not partial.exists()
    else:
        rows = partial.read_text().splitlines()
        assert len(rows) >= 3 and rows[0].startswith("run,")


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_the_workers_of_a_batch_killed_alone_end_with_it(tmp_path):
    """kill -9 of the batch process alone (the out-of-memory killer, `timeout -s KILL`, a
    `kill -9 PID`) left its workers running their runs and then waiting for work forever (a
    forked worker holds both ends of its pipe, so it never reads an end of file)."""
    import os
    import subprocess
    import sys
    import time

    ctrl = tmp_path / "busy.py"
    ctrl.write_text("import os\ndef main(s):\n    open(f'started.{os.getpid()}', 'w').close()\n"
                    "    while True:\n        pass\n")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    proc = subprocess.Popen([sys.executable, "-c", "from simrunner.cli import main; main()", "batch", str(ctrl),
                             "--seeds", "2", "--workers", "2", "--wall-limit", "300", "--no-plot",
                             "-o", str(tmp_path / "out")], cwd=tmp_path, env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while len(list(tmp_path.glob("started.*"))) < 2 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        assert len(list(tmp_path.glob("started.*"))) == 2 and proc.poll() is None
        assert kill_alone_and_wait_for_its_session(proc) == []  # its process only, not its group
    finally:
        kill_session(proc)  # what is left of it


def _summary_rows():
    """Two tracks x three speeds: laps on one track, every run off the road on the other,
    two of them at the same place."""
    rows = []
    for track in ("a.txt", "b.txt"):
        for v in (1.0, 2.0, 3.0):
            ok = track == "a.txt"
            rows.append(dict(track=track, v=v, outcome="finished" if ok else "off_track",
                             best_lap_s=12.0 / v if ok else None, off_progress_frac=None if ok else (0.3 if v < 3 else 0.7)))
    return rows


def test_summary_plot_legends_hide_no_data_and_runs_at_one_place_stay_apart(tmp_path, monkeypatch):
    """summary.png: the legends sat inside the panels (the outcomes' over the tallest bar), and
    off-road runs of different parameters at one place of a track were one marker."""
    from simrunner.workflows.batch import plot as batch_plot
    from helpers import legends_off_the_panels

    drawn = []
    monkeypatch.setattr("matplotlib.pyplot.close", drawn.append)
    batch_plot.plot_summary(_summary_rows(), ("v",), tmp_path / "summary.png")
    fig, = drawn
    fig.canvas.draw()
    legends_off_the_panels(fig)
    where = fig.axes[2].collections  # one marker series per parameter combination
    xs = [tuple(c.get_offsets()[:, 0]) for c in where]
    assert len(xs) == 3 and len(set(xs)) == 3


def test_summary_plot_without_any_lap_says_so(tmp_path, monkeypatch):
    """A batch whose runs all left the road drew its lap-time panel on a -0.04..0.04 s scale,
    the no-lap crosses at '0 s'; the panel now says no run completed a lap, with no time scale."""
    from simrunner.workflows.batch import plot as batch_plot

    drawn = []
    monkeypatch.setattr("matplotlib.pyplot.close", drawn.append)
    rows = [r for r in _summary_rows() if r["best_lap_s"] is None]
    batch_plot.plot_summary(rows, ("v",), tmp_path / "summary.png")
    ax = drawn[0].axes[0]
    assert list(ax.get_yticks()) == []
    assert any("no run completed a lap" in t.get_text() for t in ax.texts)
