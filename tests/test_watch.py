"""`simrunner drive --watch`: the track stays loaded, each save of the controller re-runs it."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from simrunner.run.watch import watch_runs

REPO = Path(__file__).resolve().parents[1]
CONTROLLER = """SPEED = {speed}
def main(spinner):
    for _ in range(10):
        spinner.get_image(spinner.line_row)
        spinner.set_speed_and_servo(SPEED, 0.0)
"""


def _save(path: Path, text: str) -> None:
    """Write ``text`` so that the watcher sees a new file (a later modification time)."""
    before = path.stat().st_mtime_ns if path.exists() else 0
    path.write_text(text)
    if path.stat().st_mtime_ns == before:  # coarse file-system clock: move it on
        os.utime(path, ns=(before + 1_000_000, before + 1_000_000))


def test_each_save_runs_the_new_code(tmp_path):
    ctrl = tmp_path / "ctrl.py"
    _save(ctrl, CONTROLLER.format(speed=1.0))
    deadline = time.monotonic() + 60
    runs = watch_runs(ctrl, poll_s=0.01, stop=lambda: time.monotonic() > deadline, max_runs=3)
    first = next(runs)
    assert first.number == 1 and first.error is None
    assert first.result.outcome == "controller_returned"
    track = first.result.track
    _save(ctrl, CONTROLLER.format(speed=0.5))
    second = next(runs)
    assert second.number == 2 and second.error is None
    assert second.result.track == track  # the same loaded track
    # the second run drove the saved code: half the commanded speed
    assert first.result.log.speed_cmd_mps.max() == pytest.approx(1.0)
    assert second.result.log.speed_cmd_mps.max() == pytest.approx(0.5)
    _save(ctrl, "def main(spinner:\n")  # a save in the middle of typing
    third = next(runs)
    assert third.result is None and third.error.startswith(f"{ctrl}:1: syntax error")
    assert next(runs, None) is None  # max_runs
    assert time.monotonic() < deadline


def test_watch_waits_without_a_save(tmp_path):
    ctrl = tmp_path / "ctrl.py"
    _save(ctrl, CONTROLLER.format(speed=1.0))
    deadline = time.monotonic() + 0.5
    events = list(watch_runs(ctrl, poll_s=0.01, stop=lambda: time.monotonic() > deadline))
    assert [e.number for e in events] == [1]


def _read_until(proc, marker: str, timeout_s: float) -> list[str]:
    lines, end = [], time.monotonic() + timeout_s
    while time.monotonic() < end:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if marker in line:
            return lines
    raise AssertionError(f"no {marker!r} within {timeout_s} s: {''.join(lines)}")


def test_cli_watch_prints_a_result_per_save_and_ends_on_ctrl_c(tmp_path):
    ctrl = tmp_path / "ctrl.py"
    _save(ctrl, CONTROLLER.format(speed=1.0))
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    err = (tmp_path / "stderr.txt").open("w")  # a file, not a pipe nobody reads: never blocks the child
    # the child as started from a terminal: a test run launched in the background (bash: `cmd &`)
    # passes SIGINT on ignored, and Python then keeps ignoring it (Ctrl-C would do nothing)
    proc = subprocess.Popen([sys.executable, "-u", "-c", "from simrunner.cli import main; main()",
                             "drive", str(ctrl), "--watch"], stdout=subprocess.PIPE,
                            stderr=err, text=True, env=env, cwd=tmp_path,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        out = _read_until(proc, "[run 1] waiting", 60)
        assert any("[run 1] outcome: controller_returned" in ln for ln in out), out
        _save(ctrl, CONTROLLER.format(speed=0.5))
        out = _read_until(proc, "[run 2] waiting", 60)
        assert any("[run 2] laps: 0/1" in ln and "after the save" in ln for ln in out), out
        proc.send_signal(signal.SIGINT)
        try:
            code = proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            rest, _ = proc.communicate()
            raise AssertionError(f"no exit 30 s after Ctrl-C; stdout after run 2: {rest!r}; "
                                 f"stderr: {(tmp_path / 'stderr.txt').read_text()!r}") from None
        assert code == 130, (tmp_path / "stderr.txt").read_text()
    finally:
        err.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_cli_watch_bad_track_is_exit_2(tmp_path):
    ctrl = tmp_path / "ctrl.py"
    _save(ctrl, CONTROLLER.format(speed=1.0))
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run([sys.executable, "-c", "from simrunner.cli import main; main()", "drive",
                           str(ctrl), "--watch", "--track", str(tmp_path / "nope.txt")],
                          capture_output=True, text=True, env=env, timeout=60)
    assert done.returncode == 2 and "no such track" in done.stderr
    assert "Traceback" not in done.stderr
