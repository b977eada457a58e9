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
