"""Runs that end without the simulator's say (issue 13 items 13 and 16): a hard kill
(SIGKILL) and a controller stuck inside one C-level call that holds the interpreter.

The run log is streamed one whole row per write, so after a hard kill every closed row is on
disk and the file reads back; a last row cut short mid-write is left out with a warning."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from simrunner.telemetry.log import LogWarning, read_log

REPO = Path(__file__).resolve().parents[1]
PY = sys.executable


def start_drive(tmp_path: Path, body: str, *options: str) -> subprocess.Popen:
    """``simrunner drive ctrl.py`` in its own session (so the test can end the whole group)."""
    (tmp_path / "ctrl.py").write_text("import os, sys, time\ndef main(s):\n"
                                      + textwrap.indent(textwrap.dedent(body), "    "))
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.Popen([PY, "-c", "from simrunner.cli import main; main()", "drive", "ctrl.py",
                             *options], cwd=tmp_path, env=env, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for(path: Path, proc: subprocess.Popen, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not path.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert path.exists(), proc.communicate(timeout=10)


def test_sigkill_mid_run_keeps_every_closed_row(tmp_path):
    proc = start_drive(tmp_path, """\
        k = 0
        while True:
            s.add_data([f"frame text {k}, \\"quoted\\""])
            s.get_image()
            k += 1
            if k == 50:
                open("started", "w").close()
        """, "--csv", "t.csv", "--time-limit", "1e5")
    try:
        wait_for(tmp_path / "started", proc)
        os.killpg(proc.pid, signal.SIGKILL)  # the command and everything it started
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL
    log = read_log(tmp_path / "t.csv")  # the project's reader takes it as it is
    assert len(log) >= 50  # rows 0..49 were closed before the marker was written
    assert log.frame.tolist() == list(range(len(log)))  # no gap, no half row
    assert log.data_text[:50] == tuple(f'frame text {k}, "quoted"' for k in range(50))


CUT_FILE = ("# nxpcup-sim run log, format 2\n"
            "frame,t_s,data_text\n"
            "0,0.000000,\n"
            '1,0.020000,"two\nlines, ""quoted"""\n'
            "2,0.040000,last\n")


@pytest.mark.parametrize("cut", [1, 3, 8, 15, 17, 22, 30])
def test_a_last_row_cut_short_is_left_out_with_a_warning(tmp_path, cut):
    path = tmp_path / "t.csv"
    text = CUT_FILE[:len(CUT_FILE) - cut]
    path.write_text(text)
    whole, line = (2, 6) if cut < 16 else (1, 4)  # the cut falls in row 2, or in row 1 (quoted)
    with pytest.warns(LogWarning, match=rf"t\.csv:{line}: the last row is cut short"):
        log = read_log(path)
    assert log.frame.tolist() == list(range(whole))
    if whole == 2:
        assert log.data_text[1] == 'two\nlines, "quoted"'


def test_a_whole_log_reads_without_warning(tmp_path, recwarn):
    path = tmp_path / "t.csv"
    path.write_text(CUT_FILE)
    assert len(read_log(path)) == 3 and not recwarn.list
    path.write_text("t_s,x_m\n0,1\n0.1,2")  # not a run log of this simulator: the last line counts
    assert len(read_log(path)) == 2 and not recwarn.list


def _finish(proc, timeout_s: float = 120.0) -> tuple[str, str]:
    """``proc``'s output once it ends (its process group killed if it outlives the test)."""
    try:
        return proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def test_a_controller_stuck_in_one_c_call_keeps_every_output(tmp_path):
    """``sum(range(10**13))`` holds the interpreter: no Python code runs in the run's process.
    The hard watchdog ends it; the supervisor writes summary, plot and video from the log."""
    import json

    import cv2

    proc = start_drive(tmp_path, """\
        for _ in range(10):
            s.set_speed_and_servo(0.3, 0.0)
            s.add_data(["before the stall"])
            s.get_image()
        sum(range(10 ** 13))
        """, "--csv", "t.csv", "--video", "v.mp4", "--plot", "p.png", "--summary", "s.json",
                       "--wall-limit", "0.5")
    out, err = _finish(proc)
    assert proc.returncode == 1, err
    assert 'ctrl.py", line 7 in main' in err  # the stack dump, with the controller's line
    assert "runner.py" not in err and "Timeout (" not in err  # ... not the simulator's frames
    log = read_log(tmp_path / "t.csv")
    assert log.frame.tolist() == list(range(10))  # rows 0..9 closed; row 10 was still open
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["outcome"] == "stalled" and "at ctrl.py:7 in main" in summary["message"]
    assert summary["frames"] == 10 and summary["sim_time_s"] == pytest.approx(float(log.t_s[-1]))
    assert set(summary["outputs"]) == {"csv", "video", "plot", "summary"}
    assert "outcome: stalled" in out
    assert cv2.imread(str(tmp_path / "p.png")) is not None
    assert not (tmp_path / "v.partial.mp4").exists()
    cap = cv2.VideoCapture(str(tmp_path / "v.mp4"))
    frames = 0
    while cap.read()[0]:
        frames += 1
    cap.release()
    assert frames == 5  # every second row: the video keeps at most 30 fps of the 50 fps camera


def test_without_csv_the_stuck_run_still_gets_its_summary(tmp_path):
    import json

    proc = start_drive(tmp_path, """\
        for _ in range(5):
            s.get_image()
        sum(range(10 ** 13))
        """, "--summary", "s.json", "--wall-limit", "0.5")
    out, err = _finish(proc)
    assert proc.returncode == 1, err
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["outcome"] == "stalled" and summary["frames"] == 5
    assert summary["outputs"] == {"summary": "s.json"}  # the supervisor's run log is not an output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ctrl.py", "s.json"]


@pytest.mark.parametrize("how, signame", [("os.kill(os.getpid(), 9)", "SIGKILL"),
                                          ("__import__('ctypes').string_at(0)", "SIGSEGV")])
def test_a_run_process_killed_by_a_signal_still_gets_its_outputs(tmp_path, how, signame):
    """Issue 50 (fault injection): the out-of-memory killer's SIGKILL, or a crash the run cannot
    catch, ended `drive` with 137/139 and nothing written: the supervisor writes the summary
    and the plot from the run log, outcome controller_error naming the signal."""
    import json

    body = "s.sleep(0.3)\nimport signal\nsignal.signal(signal.SIGSEGV, signal.SIG_DFL)\n" + how + "\n"
    proc = start_drive(tmp_path, body, "--summary", "s.json", "--plot", "p.png")
    try:
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 1, (out, err)
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["outcome"] == "controller_error"
    import re

    assert re.search(rf"killed by {signame} at t = 0\.[23]\d\d s", summary["message"]), summary["message"]
    assert (tmp_path / "p.png").stat().st_size > 1000 and "Traceback" not in err


def test_the_stack_shown_of_a_stuck_controller_ends_at_its_outermost_frame(tmp_path):
    """Of faulthandler's dump, the thread the controller ran in, from the innermost call (in a
    module of the controller's) out to the controller's main; other threads and the simulator's
    frames left out. A dump without the controller's frames is shown whole."""
    from simrunner.run.postmortem import stuck_stack

    ctrl = tmp_path / "ctrl.py"
    dump = (f"Timeout (0:00:03)!\n"
            f"Thread 0x00007f01 (most recent call first):\n"
            f'  File "/usr/lib/python3.11/threading.py", line 320 in wait\n'
            f"\n"
            f"Thread 0x00007f00 (most recent call first):\n"
            f'  File "{tmp_path}/helper.py", line 3 in crunch\n'
            f'  File "{ctrl}", line 9 in step\n'
            f'  File "{ctrl}", line 14 in main\n'
            f'  File "/x/simrunner/run/runner.py", line 392 in execute\n'
            f'  File "/x/simrunner/cli/__init__.py", line 314 in run\n')
    shown = stuck_stack(dump, str(ctrl)).splitlines()
    assert shown[1:] == [f'  File "{tmp_path}/helper.py", line 3 in crunch', f'  File "{ctrl}", line 9 in step',
                         f'  File "{ctrl}", line 14 in main']
    assert stuck_stack(dump, str(tmp_path / "other.py")) == dump.rstrip()


@pytest.mark.skipif(sys.platform != "linux", reason="prctl(2): Linux")
def test_a_run_process_whose_parent_died_first_ends_also_under_a_subreaper(tmp_path):
    """die_with_parent with the parent's pid: a process whose parent died before its prctl call
    ends at once also where orphans go to a subreaper (containers, systemd user sessions), not
    to init; without the pid, only an orphan of init is seen (a forkserver's child)."""
    script = textwrap.dedent("""\
        import ctypes, os, sys, time
        from simrunner.run.supervise import die_with_parent
        ctypes.CDLL(None).prctl(36, 1)  # PR_SET_CHILD_SUBREAPER: orphans below come to this process
        with_pid = sys.argv[1] == "pid"
        r, w = os.pipe()
        middle = os.fork()
        if middle == 0:
            parent = os.getpid()
            if os.fork() == 0:  # the run process: its parent is gone before it calls
                while os.getppid() == parent:
                    time.sleep(0.01)
                try:
                    die_with_parent(parent if with_pid else None)
                    os.write(w, b"alive")
                except BaseException as exc:
                    os.write(w, repr(exc).encode())
                os._exit(0)
            os._exit(0)
        os.waitpid(middle, 0)
        os.close(w)
        print(os.read(r, 200).decode() or "ended")
        """)
    out = {how: subprocess.run([sys.executable, "-c", script, how], capture_output=True, text=True,
                               timeout=30, cwd=REPO).stdout.strip() for how in ("pid", "none")}
    assert out == {"pid": "ended", "none": "alive"}


def test_temporary_folders_of_killed_processes_are_removed_by_the_next_one(tmp_path, monkeypatch):
    """A drive or batch killed by SIGKILL leaves its temporary folder (nothing of it runs to
    remove it): the next one of its kind removes those whose process is gone, if older than a
    minute; a live process's and a fresh one stay."""
    import tempfile

    from simrunner.run.supervise import private_temp_dir

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    old = time.time() - 120.0
    folders = {name: tmp_path / name for name in (
        f"simrunner-batch-{gone.pid}-a1", f"simrunner-batch-{os.getppid()}-b2",
        f"simrunner-run-{gone.pid}-c3", "simrunner-batch-ray-d4")}
    for folder in folders.values():
        (folder / "worker1.report").parent.mkdir()
        (folder / "worker1.report").write_text("x")
        os.utime(folder, (old, old))
    fresh = tmp_path / f"simrunner-batch-{gone.pid}-e5"
    fresh.mkdir()
    made = private_temp_dir("batch")
    assert made.parent == tmp_path and made.name.startswith(f"simrunner-batch-{os.getpid()}-")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [made.name, fresh.name, f"simrunner-batch-{os.getppid()}-b2", f"simrunner-run-{gone.pid}-c3",
         "simrunner-batch-ray-d4"])


def test_a_run_killed_before_its_first_frame_still_writes_the_asked_csv(tmp_path):
    """A run whose process died before its first row (a crash in a C constructor, say) was
    told as ``wrote: out.csv`` with no such file: the CSV asked for is now written with the
    columns' header and no row, and reads back as an empty run log."""
    import json

    from simrunner.telemetry.log import read_log

    body = "import signal\nsignal.signal(signal.SIGSEGV, signal.SIG_DFL)\n__import__('ctypes').string_at(0)\n"
    proc = start_drive(tmp_path, body, "--csv", "out.csv", "--summary", "s.json")
    out, err = _finish(proc)
    assert proc.returncode == 1, (out, err)
    summary = json.loads((tmp_path / "s.json").read_text())
    assert "killed by SIGSEGV before the first frame" in summary["message"]
    assert summary["outputs"]["csv"] == "out.csv" and "wrote: out.csv" in out
    assert len(read_log(tmp_path / "out.csv")) == 0


def test_a_killed_run_that_drew_long_texts_still_gets_its_outputs(tmp_path):
    """A run log whose add_data text is longer than the csv module's default field limit
    (128 KiB) read back as 'expected valid CSV (field larger than field limit (131072))': the
    supervisor of a killed run wrote no outputs. The reader now takes any field the writer wrote."""
    import json

    from simrunner.telemetry.log import read_log

    body = ("import signal\nsignal.signal(signal.SIGSEGV, signal.SIG_DFL)\nfor _ in range(3):\n"
            "    s.add_data(['x' * 200000])\n    s.get_image()\n__import__('ctypes').string_at(0)\n")
    proc = start_drive(tmp_path, body, "--csv", "out.csv", "--summary", "s.json")
    out, err = _finish(proc)
    assert proc.returncode == 1, (out, err)
    summary = json.loads((tmp_path / "s.json").read_text())
    assert "killed by SIGSEGV" in summary["message"] and summary["frames"] >= 3, summary
    assert max(len(t) for t in read_log(tmp_path / "out.csv").data_text) >= 200000
