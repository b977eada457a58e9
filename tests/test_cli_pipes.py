"""A reader of the CLIs' stdout that goes away (``simrunner drive ctl.py | head -n1``, issue 50):
no BrokenPipeError traceback, and the run is the one it would have been with a reader."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SIMRUNNER = "from simrunner.cli import main; main()"
TRACKGEN = "from trackgen.cli import main; main()"


def _run(code: str, args: list[str], *, reader_gone: bool, cwd: Path) -> subprocess.CompletedProcess:
    """The command with stdout a pipe whose reader has already gone (``reader_gone``), else
    /dev/null; stderr captured."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    if not reader_gone:
        return subprocess.run([sys.executable, "-c", code, *args], stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True, env=env, cwd=cwd, timeout=300)
    r, w = os.pipe()
    os.close(r)  # the reader left before the first line
    try:
        return subprocess.run([sys.executable, "-c", code, *args], stdout=w, stderr=subprocess.PIPE,
                              text=True, env=env, cwd=cwd, timeout=300)
    finally:
        os.close(w)


CHATTY_PY = """\
    def main(spinner):
        for i in range(100):
            print("frame", i)
            spinner.get_image(60, 1)
            spinner.set_speed_and_servo(0.5, 0.0)
    """
CHATTY_C = """\
    #include <stdio.h>
    #include "spinner.h"
    int main(void) {
        uint8_t row[128];
        for (int i = 0; i < 100; i++) {
            printf("frame %d\\n", i);
            spinner_get_image(60, 1, row, sizeof row);
            spinner_set_speed_and_servo(0.5, 0.0);
        }
        return 0;
    }
    """


@pytest.mark.parametrize("name, body, extra", [
    ("chatty.py", CHATTY_PY, []),
    pytest.param("chatty.c", CHATTY_C, ["--isolate"], marks=pytest.mark.skipif(
        shutil.which("cc") is None, reason="no C compiler")),
])
def test_drive_whose_reader_left_runs_as_with_a_reader_and_shows_no_traceback(tmp_path, name, body,
                                                                               extra):
    """Before: the controller's print raised BrokenPipeError (the run ended as controller_error
    with that traceback, exit 141); an isolated C program was killed by SIGPIPE."""
    (tmp_path / name).write_text(textwrap.dedent(body))
    ends = []
    for gone in (False, True):
        summary = tmp_path / f"summary_{gone}.json"
        done = _run(SIMRUNNER, ["drive", name, "--track", "floor", "--time-limit", "5",
                                "--summary", str(summary), *extra], reader_gone=gone, cwd=tmp_path)
        assert "Traceback" not in done.stderr and "SIGPIPE" not in done.stderr, done.stderr
        ends.append((done.returncode, json.loads(summary.read_text())["outcome"]))
    assert ends[0] == ends[1] == (0, "controller_returned")


def test_trackgen_whose_reader_left_shows_no_traceback(tmp_path):
    done = _run(TRACKGEN, ["random", "--seed", "1"], reader_gone=True, cwd=tmp_path)
    assert done.returncode == 1 and done.stderr == ""
