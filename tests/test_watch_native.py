"""`simrunner drive --watch` for C/C++ controllers: each save of a source or a header of an
include folder rebuilds and re-runs; a compile error is reported and the next save awaited."""
from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from simrunner.run.watch import watch_runs

C_CONTROLLER = """#include "spinner.h"
#include "speed.h"
int main(void) {
    for (int i = 0; i < 10; i++) {
        uint8_t row[1024];
        spinner_get_image(spinner_line_row(), 1, row, sizeof row);
        spinner_set_speed_and_servo(SPEED, 0.0);
    }
    return 0;
}
"""


def _save(path: Path, text: str) -> None:
    before = path.stat().st_mtime_ns if path.exists() else 0
    path.write_text(text)
    if path.stat().st_mtime_ns == before:
        os.utime(path, ns=(before + 1_000_000, before + 1_000_000))


def test_a_c_controller_is_rebuilt_on_each_save_of_a_source_or_header(tmp_path):
    from simrunner.cli import _native_program

    inc = tmp_path / "inc"
    inc.mkdir()
    src = tmp_path / "ctrl.c"
    _save(src, C_CONTROLLER)
    header = inc / "speed.h"
    _save(header, "#define SPEED 1.0\n")
    deadline = time.monotonic() + 120
    runs = watch_runs(src, poll_s=0.01, stop=lambda: time.monotonic() > deadline, max_runs=3,
                      make=lambda: _native_program(str(src), (), (str(inc),), ()),
                      watched=(src, header))
    first = next(runs)
    assert first.error is None and first.result.log.speed_cmd_mps.max() == pytest.approx(1.0)
    _save(header, "#define SPEED 0.5\n")  # a header of an include folder
    second = next(runs)
    assert second.error is None and second.result.log.speed_cmd_mps.max() == pytest.approx(0.5)
    _save(src, C_CONTROLLER.replace("return 0;", "return 0"))  # a save in the middle of typing
    third = next(runs)
    assert third.result is None and "ctrl.c" in third.error


def test_the_headers_beside_the_sources_are_watched_too(tmp_path):
    """`#include "pid.h"` next to the controller needs no -I (the compiler looks in the
    source's folder), but a save of pid.h did not re-run the watch: only -I folders' headers
    were watched."""
    from simrunner.run.watch import native_watched

    (tmp_path / "inc").mkdir()
    for name in ("main.c", "pid.h", "notes.txt", "inc/speed.hpp", "more.cpp"):
        (tmp_path / name).write_text("")
    files = native_watched(tmp_path / "main.c", [tmp_path / "more.cpp"], [tmp_path / "inc"])
    assert sorted(Path(f).relative_to(tmp_path).as_posix() for f in files) == [
        "inc/speed.hpp", "main.c", "more.cpp", "pid.h"]


@pytest.mark.parametrize("name, said", [
    ("boom.c", "boom.c:5: SIGSEGV: segmentation fault (in boom())"),
    ("exit3.c", "the controller called exit(3) at exit3.c:4, in a constructor as the program loaded")])
def test_a_constructor_that_ends_the_program_at_its_load_ends_a_run_not_the_watch(tmp_path, name, said):
    """A fault or an exit in a C constructor runs as the program's library is loaded: in the watch's
    own process (no supervisor there) it ended the whole watch session (killed by SIGSEGV; status 70)
    before any outcome line. The watch runs C/C++ programs isolated: the run's outcome is --isolate's,
    and the next save runs again."""
    import signal
    import subprocess
    import sys
    import threading

    from helpers import C_CTOR_ENDS, C_CTOR_FAULT

    src = tmp_path / name
    _save(src, C_CTOR_FAULT if name == "boom.c" else C_CTOR_ENDS[name][0])
    # (as test_watch's: unbuffered, stderr to a file, SIGINT as from a terminal)
    with (tmp_path / "stderr.txt").open("w") as errors:
        proc = subprocess.Popen([sys.executable, "-u", "-c", "from simrunner.cli import main; main()", "drive", name,
                                 "--watch", "--time-limit", "0.2"], cwd=tmp_path, stdout=subprocess.PIPE,
                                stderr=errors, text=True,
                                env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])},
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        guard = threading.Timer(240, proc.kill)
        guard.start()
        lines = []
        try:
            for line in proc.stdout:
                lines.append(line.rstrip("\n"))
                if line.startswith("[run 1] waiting"):
                    _save(src, '#include "spinner.h"\nint main(void) { spinner_sleep(0.05); return 0; }\n')
                if line.startswith("[run 2] waiting"):
                    # (once it waits: a SIGINT that lands in its write of this line raises there and
                    # its stdout's flush at exit fails: status 120 - not what this test is about)
                    time.sleep(0.5)
                    proc.send_signal(signal.SIGINT)
            proc.wait(timeout=60)
        finally:
            guard.cancel()
            proc.kill()
    err = (tmp_path / "stderr.txt").read_text()
    assert proc.returncode == 130, (proc.returncode, lines, err[-2000:])
    assert f"[run 1] outcome: controller_error ({said})" in lines, (lines, err[-2000:])
    assert any(t.startswith("[run 2] outcome: controller_returned") for t in lines), lines
