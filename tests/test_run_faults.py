"""Controller faults that used to lose a run (issue 13 item 13), silent wrong behaviour turned
into a message (item 7), and the run log written as the run goes (item 16).

Each fault kind is a row of a table; the process-level ones run the CLI in a subprocess
(short runs: a few camera frames, then the fault)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import cv2
import pytest
from hypothesis import given, settings, strategies as st

from simrunner.errors import SimError
from simrunner.run.faults import exit_code
from simrunner.telemetry.log import RunRecorder, read_log, to_csv_text
from simrunner.run.runner import Run, drive, resolve_track
from simrunner.run.settings import RunSettings
from vehicle.description import CarDescription

REPO = Path(__file__).resolve().parents[1]
PY = sys.executable

# ten camera frames driving, then the fault (line 6 of every controller)
HEAD = """\
import os, sys, threading, time
def main(s):
    for _ in range(10):
        s.set_speed_and_servo(0.3, 0.0)
        s.get_image()
"""


def controller(tmp_path: Path, fault: str, name: str = "ctrl.py", head: str = HEAD) -> Path:
    path = tmp_path / name
    path.write_text(head + textwrap.indent(textwrap.dedent(fault), "    "))
    return path


def cli(*args, cwd: Path, timeout: float = 60.0) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run([PY, "-c", "from simrunner.cli import main; main()", "drive", *map(str, args)],
                          cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def video_frames(path: Path) -> int:
    cap = cv2.VideoCapture(str(path))
    try:
        n = 0
        while cap.read()[0]:
            n += 1
        return n
    finally:
        cap.release()


# -- sys.exit / SystemExit / os._exit: in-process table ---------------------------------------
EXITS = [  # (fault, outcome, exit code)
    ("sys.exit(3)", "controller_error", 1),
    ("sys.exit(0)", "controller_returned", 0),
    ("sys.exit()", "controller_returned", 0),
    ("raise SystemExit", "controller_returned", 0),
    ("sys.exit('bye')", "controller_error", 1),
    ("os._exit(0)", "controller_returned", 0),
    ("os._exit(5)", "controller_error", 1),
]


@pytest.mark.parametrize("fault, outcome, code", EXITS)
def test_exits_in_a_controller_end_the_run_and_keep_everything(tmp_path, fault, outcome, code):
    ctrl = controller(tmp_path, fault)
    r = drive(ctrl, csv=tmp_path / "t.csv", summary=tmp_path / "s.json")
    assert r.outcome == outcome and exit_code(r.outcome, r.signal) == code
    assert "ctrl.py:6" in r.message  # the line of the exit
    assert len(read_log(tmp_path / "t.csv")) == 11  # frames 0..10: every row
    assert json.loads((tmp_path / "s.json").read_text())["outcome"] == outcome
    if code:
        assert "ctrl.py\", line 6" in r.error.traceback_text
    assert os._exit.__module__ == "posix" and time.sleep.__module__ == "time"  # restored


def test_exit_at_the_top_level_of_the_controller_file(tmp_path):
    ctrl = controller(tmp_path, "", head="import sys\nsys.exit(2)\ndef main(s):\n    pass\n")
    r = drive(ctrl, csv=tmp_path / "t.csv")
    assert r.outcome == "controller_error" and "ctrl.py:2" in r.message
    assert len(read_log(tmp_path / "t.csv")) == 1  # frame 0, the initial state


# -- faults beyond exits: one table; "process" rows need a process of their own ----------------
FAULTS = [  # (id, fault, extra options, exit code, text in the output, process)
    ("sys_exit_video", "sys.exit(3)", ("--video", "v.mp4"), 1, "called sys.exit(3) at ctrl.py:6", True),
    ("os_exit_video", "os._exit(0)", ("--video", "v.mp4"), 0, "called os._exit(0) at ctrl.py:6", False),
    ("c_level_loop", "sum(range(10 ** 13))", ("--wall-limit", "0.5"), 1, 'ctrl.py", line 6 in main', True),
    ("non_daemon_thread", """\
        def forever():
            while True:
                time.sleep(0.05)
        threading.Thread(target=forever, name="worker").start()
        """, (), 0, "left thread 'worker' (ctrl.py:6) running", True),
    ("thread_uses_spinner", """\
        t = threading.Thread(target=s.get_image, name="helper")
        t.start()
        t.join()
        s.get_image()
        """, (), 1, "Spinner.get_image() called from thread 'helper'", False),
    ("thread_builds_spinner", """\
        from simrunner import Spinner
        t = threading.Thread(target=lambda: Spinner().get_image(), name="helper")
        t.start()
        t.join()
        s.get_image()
        """, (), 1, "Spinner.__init__() called from thread 'helper'", False),
]


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")  # the helpers'
@pytest.mark.parametrize("fault, options, code, text, process", [p[1:] for p in FAULTS],
                         ids=[p[0] for p in FAULTS])
def test_faults_keep_the_run_and_say_what_happened(tmp_path, fault, options, code, text, process):
    ctrl = controller(tmp_path, fault)
    if process:
        t0 = time.monotonic()
        res = cli("ctrl.py", "--csv", "t.csv", *options, cwd=tmp_path, timeout=90)
        assert time.monotonic() - t0 < 85  # the process ends (no thread keeps it alive)
        assert res.returncode == code, res.stderr
        assert "terminate called" not in res.stderr
        output = res.stderr + res.stdout
    else:
        video = tmp_path / "v.mp4" if "--video" in options else None
        r = drive(ctrl, csv=tmp_path / "t.csv", video=video)
        assert exit_code(r.outcome, r.signal) == code
        output = r.message + "".join(r.warnings)
    assert text in output
    rows = read_log(tmp_path / "t.csv")
    assert len(rows) >= 10 and list(rows.frame[:10]) == list(range(10))  # written as it went
    if "--video" in options:
        assert not (tmp_path / "v.partial.mp4").exists()
        assert video_frames(tmp_path / "v.mp4") == (len(rows) + 1) // 2  # every second frame (50 fps)


def test_a_spinner_call_from_a_thread_is_said_once_without_the_threads_traceback(tmp_path):
    """The run's outcome names the call and its line; the thread's own traceback (through the
    simulator's frames) is not printed too. A thread's other exceptions print as Python prints them."""
    ctrl = controller(tmp_path, """\
        def boom():
            raise ValueError("own fault")
        own = threading.Thread(target=boom, name="mine")
        own.start()
        own.join()
        t = threading.Thread(target=s.get_image, name="helper")
        t.start()
        t.join()
        s.get_image()
        """)
    res = cli("ctrl.py", cwd=tmp_path)
    assert res.returncode == 1 and "Spinner.get_image() called from thread 'helper'" in res.stdout
    assert res.stderr.count("Traceback") == 1 and "ValueError: own fault" in res.stderr, res.stderr
    assert "spinner.py" not in res.stderr


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=lambda s: s.name)
def test_termination_signals_write_every_output(tmp_path, sig):
    ctrl = controller(tmp_path, """\
        open("started", "w").close()
        while True:
            s.get_image()
        """)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen([PY, "-c", "from simrunner.cli import main; main()", "drive", ctrl.name,
                             "--csv", "t.csv", "--video", "v.mp4", "--summary", "s.json",
                             "--time-limit", "1e5"], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not (tmp_path / "started").exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 128 + sig, err
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["outcome"] == "interrupted" and sig.name in summary["message"]
    log = read_log(tmp_path / "t.csv")
    assert len(log) == summary["frames"] > 10
    assert not (tmp_path / "v.partial.mp4").exists() and video_frames(tmp_path / "v.mp4") > 10


# -- time.sleep, speed cap, time limit (item 7) -------------------------------------------------
def test_time_sleep_in_a_controller_waits_in_simulated_time(tmp_path):
    ctrl = controller(tmp_path, """\
        t0 = s.get_time()
        time.sleep(0.5)
        from time import sleep
        sleep(0.25)
        s.add_data([f"{s.get_time() - t0:.3f}"])
        s.get_image()
        """)
    wall0 = time.monotonic()
    r = drive(ctrl, csv=tmp_path / "t.csv")
    assert time.monotonic() - wall0 < 30
    assert r.outcome == "controller_returned"
    texts = [t for t in read_log(tmp_path / "t.csv").data_text if t]
    assert texts == ["0.752"]  # 0.5 + 0.25 s simulated, plus one step of get_time


def test_speed_above_the_maximum_is_capped_with_one_warning(tmp_path):
    ctrl = controller(tmp_path, """\
        for v in (5.0, 7.0, -9.0):
            s.set_speed(v)
            s.get_image()
        """)
    r = drive(ctrl)
    assert len(r.warnings) == 1
    assert "speed command 5 m/s at ctrl.py:7" in r.warnings[0] and "3.1 m/s" in r.warnings[0]
    assert r.log.speed_mps.max() <= 3.1 + 1e-9


def test_no_warning_within_the_car_limits(tmp_path):
    assert drive(controller(tmp_path, "s.set_speed(-3.1)\ns.get_image()\n")).warnings == []


def test_time_limit_grows_with_the_laps():
    car = CarDescription()
    track, _ = resolve_track(None, car)  # the thesis figure-8, 14.74 m
    assert RunSettings().time_limit_s is None
    for laps, limit in ((1, 60.0), (3, 3 * track.lap_length_m / 0.5), (10, 10 * track.lap_length_m / 0.5)):
        assert Run(track, car, RunSettings(laps=laps)).settings.time_limit_s == pytest.approx(limit)
    assert Run(track, car, RunSettings(laps=10, time_limit_s=5)).settings.time_limit_s == 5.0


# -- outputs checked before driving; the CSV written as the run goes (item 16) ------------------
def _bad_outputs(tmp_path: Path) -> list[tuple[dict, str]]:
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    return [({"csv": tmp_path / "adir"}, "is a folder"),
            ({"summary": tmp_path / "adir"}, "is a folder"),
            ({"csv": tmp_path / "afile" / "t.csv"}, "is not a folder"),
            ({"video": tmp_path / "v.avi"}, "expected a .mp4 file"),
            ({"csv": tmp_path / "same", "summary": tmp_path / "same"}, "the same file as --csv"),
            ({"csv": ""}, "expected a file path")]


def test_bad_output_paths_are_refused_before_the_run(tmp_path):
    marker = tmp_path / "ran"
    ctrl = controller(tmp_path, "", head=f"open({str(marker)!r}, 'w').close()\ndef main(s):\n    pass\n")
    for outputs, text in _bad_outputs(tmp_path):
        with pytest.raises(SimError, match=text):
            drive(ctrl, **outputs)
        assert not marker.exists()  # the controller was not even loaded
    res = cli(ctrl, "--csv", tmp_path / "adir", cwd=tmp_path)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "--csv" in res.stderr


def test_streamed_csv_has_the_bytes_of_write_log(tmp_path):
    ctrl = controller(tmp_path, """\
        for i in range(5):
            s.add_data([f'say "hi", {i}', "line\\ntwo"])
            s.get_image()
        """)
    r = drive(ctrl, csv=tmp_path / "t.csv")
    assert (tmp_path / "t.csv").read_text() == to_csv_text(r.log)
    assert r.summary()["frames"] == len(r.log) == 16


def test_csv_rows_are_on_disk_while_the_run_goes(tmp_path):
    csv = tmp_path / "t.csv"
    ctrl = controller(tmp_path, f"""\
        lines = open({str(csv)!r}).read().count("\\n")
        s.add_data([str(lines)])
        s.get_image()
        """)
    drive(ctrl, csv=csv)
    assert [t for t in read_log(csv).data_text if t] == ["12"]  # format, header, rows 0..9


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 300), max_rows=st.integers(2, 40))
def test_recorder_memory_is_bounded_and_the_sink_gets_every_row(n, max_rows):
    got = []

    class Sink:
        def row(self, values, text):
            got.append((values[0], text))

    rec = RunRecorder(sink=Sink(), max_rows=max_rows)
    for k in range(n):
        rec.frame(k, 0.02 * k, *(0.0,) * 6, (float(k), 0.0, 0.0), None, 0, False)
        rec.text([f"t{k}"])
    log = rec.freeze()
    rec.finish()
    assert len(rec) == n and [g[0] for g in got] == list(range(n))
    assert [g[1] for g in got] == [f"t{k}" for k in range(n)]
    assert len(log) == n if n <= max_rows + 1 else len(log) <= max_rows + 1
    frames = log.frame.tolist()
    if n:
        assert frames[-1] == n - 1  # the last row is always there
        assert frames[:-1] == list(range(0, n - 1, rec.stride))  # every stride-th row
        assert all(t == f"t{f}" for f, t in zip(frames, log.data_text))
        assert log.speed_cmd_mps.tolist() == frames


def test_a_controllers_chdir_and_environment_stay_in_its_run(tmp_path, monkeypatch):
    """Issue 50 (fault injection): a controller that changes directory or os.environ moved the
    run's outputs and changed later runs of a batch worker."""
    import os

    from simrunner.run.runner import drive

    monkeypatch.chdir(tmp_path)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()

    def main(s):
        os.environ["NXPCUP_LEAK"] = "1"
        os.chdir(elsewhere)
        s.get_image()

    r = drive(main, track="floor", time_limit_s=1.0, csv="log.csv", summary="summary.json")
    assert r.outcome == "controller_returned"
    assert os.getcwd() == str(tmp_path) and "NXPCUP_LEAK" not in os.environ
    assert (tmp_path / "log.csv").exists() and (tmp_path / "summary.json").exists()
    assert not list(elsewhere.iterdir())


def test_a_fork_in_a_python_controller_leaves_the_run_and_its_log_whole(tmp_path, capfd):
    """Issue 50 (fault injection), as for C controllers: after os.fork() both processes went on
    with the run (frames written twice, a deadlocked orphan). Now the child's Spinner call ends
    it with a message, and a child whose main ends, ends there."""
    ctrl = tmp_path / "forker.py"
    ctrl.write_text(textwrap.dedent("""\
        import os, sys
        def main(spinner):
            for i in range(5):
                spinner.get_image(60, 1)
            first = os.fork()
            if first == 0:  # a child that only exits, with a status of its own
                sys.exit(3)
            print("first child exit", os.waitstatus_to_exitcode(os.waitpid(first, 0)[1]), flush=True)
            pid = os.fork()  # a child that goes on driving: it must not
            for i in range(10):
                spinner.get_image(60, 1)
                spinner.set_speed_and_servo(0.5, 0.0)
            print("child" if pid == 0 else "parent", "done", flush=True)
            status = os.waitpid(pid, 0)[1] if pid else 0
            print("second child exit", os.waitstatus_to_exitcode(status), flush=True)
        """))
    result = drive(ctrl, track="floor", time_limit_s=2.0, csv=tmp_path / "run.csv")
    assert result.outcome == "controller_returned"
    out, err = capfd.readouterr()
    assert out.count("done") == 1 and "parent done" in out
    assert "first child exit 3" in out and "second child exit 70" in out
    assert "which the controller fork()ed from process" in err
    frames = read_log(tmp_path / "run.csv").frame
    assert list(frames) == list(range(len(frames))) and len(frames) == 16
