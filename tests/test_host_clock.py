"""A controller reading the computer's clock (or seeding randomness from it) is told where, in
``simrunner check`` and ``drive``: the host clock stays the host's, simulated time comes through
the Spinner (simrunner.run.hostclock)."""
from __future__ import annotations

import ast
import json
import os
import shutil
import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.run.check import check_controller
from simrunner.run.hostclock import SHOWN, ClockRead, clock_warnings, python_clock_reads

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
CLOCK = "reads the computer's clock, not the simulated car's (a run goes many times faster than real time)"
PY_ADVICE = "use spinner.get_time() (simulated seconds) for loop timing and dt"
C_ADVICE = "use spinner_get_time() (simulated seconds) for loop timing and dt"
needs_cc = pytest.mark.skipif(shutil.which("cc") is None and not os.environ.get("CC"),
                              reason="no C compiler (apt-get install build-essential)")


@pytest.fixture(scope="module", autouse=True)
def cache(tmp_path_factory):
    """One build cache for the module (the host program is built once)."""
    old = os.environ.get("SIMRUNNER_CACHE_DIR")
    os.environ["SIMRUNNER_CACHE_DIR"] = str(tmp_path_factory.mktemp("native-cache"))
    yield
    if old is None:
        os.environ.pop("SIMRUNNER_CACHE_DIR", None)
    else:
        os.environ["SIMRUNNER_CACHE_DIR"] = old


@pytest.fixture(scope="module")
def track():
    from simrunner.run.runner import resolve_track
    from vehicle import CarDescription

    return resolve_track(None, CarDescription())[0]


@pytest.fixture
def here(tmp_path, monkeypatch):
    """Work in ``tmp_path`` (files named as a user names them: relative)."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def write(name: str, body: str) -> Path:
    path = Path(name)
    path.write_text(textwrap.dedent(body))
    return path


def clock_lines(texts) -> list[str]:
    return [t for t in texts if "computer's clock" in t or "makes every run different" in t]


PY_DT = """\
    import time


    def main(s):
        last = time.monotonic()
        while True:
            now = time.monotonic()
            dt = now - last
            last = now
            s.get_image(s.line_row)
            s.set_speed_and_servo(0.5, 0.0 * dt)
    """


def reads(body: str, name: str = "c.py") -> list[tuple[int, str, bool]]:
    source = textwrap.dedent(body)
    return [(r.line, r.call, r.seeds) for r in python_clock_reads(ast.parse(source), source, name)]


# -- Python ---------------------------------------------------------------------------------
def test_python_monotonic_for_dt_is_warned_at_its_lines_in_check(here, track):
    write("pid.py", PY_DT)
    report = check_controller("pid.py", track=track, seconds=0.5)
    assert clock_lines(report.warnings) == [
        f"pid.py:5: time.monotonic() {CLOCK}: {PY_ADVICE}",
        f"pid.py:7: time.monotonic() {CLOCK}: {PY_ADVICE}"]
    assert report.warnings[0].startswith("pid.py:5: ")  # first: the likely cause of what follows


def test_python_monotonic_is_warned_once_by_drive_before_the_outcome_and_in_the_summary(here):
    write("pid.py", PY_DT)
    res = CliRunner().invoke(cli, ["drive", "pid.py", "--time-limit", "0.5", "--summary", "s.json"])
    assert "outcome: timeout" in res.output, res.output
    want = f"warning: pid.py:5: time.monotonic() {CLOCK}: {PY_ADVICE}"
    assert res.stderr.count(want) == 1
    assert res.output.index(want) < res.output.index("outcome: ")
    summary = json.loads(Path("s.json").read_text())
    assert summary["warnings"][:2] == [want.removeprefix("warning: "), f"pid.py:7: time.monotonic() {CLOCK}: {PY_ADVICE}"]


def test_the_controllers_own_modules_beside_it_are_read_too(here, track):
    """A team's timing in its own module (``import pid``; a package ``teamlib/``) was not found:
    the modules the controller imports from its folder are read as it is (installed ones and the
    standard library are not), shown beside it, and read again when they change. (A package
    name of its own: this process has imported the tests' ``helpers``.)"""
    Path("team/teamlib").mkdir(parents=True)
    write("team/main.py", """\
        import json
        import numpy as np
        import pid
        from teamlib.timing import stamp


        def main(s):
            while True:
                s.get_image(s.line_row)
                s.set_speed(0.5 + 0 * pid.dt() + 0 * stamp())
        """)
    write("team/pid.py", "import time\n\n\ndef dt():\n    return time.monotonic()\n")
    write("team/teamlib/__init__.py", "")
    write("team/teamlib/timing.py", "import time\n\n\ndef stamp():\n    return time.perf_counter()\n")
    report = check_controller("team/main.py", track=track, seconds=0.2)
    assert report.ok, report.text()
    assert clock_lines(report.warnings) == [f"team/pid.py:5: time.monotonic() {CLOCK}: {PY_ADVICE}",
                                            f"team/teamlib/timing.py:5: time.perf_counter() {CLOCK}: {PY_ADVICE}"]
    write("team/pid.py", "def dt():\n    return 0.0\n")  # (the controller's own text unchanged)
    report = check_controller("team/main.py", track=track, seconds=0.2)
    assert clock_lines(report.warnings) == [f"team/teamlib/timing.py:5: time.perf_counter() {CLOCK}: {PY_ADVICE}"]


def test_aliased_imports_helpers_and_datetime_are_followed():
    assert reads("""\
        import time as t
        from time import monotonic as mono, perf_counter
        from datetime import datetime
        import datetime as dtm
        def elapsed():
            return mono()
        def main(s):
            a = t.time()
            b = perf_counter()
            c = datetime.now()
            d = dtm.date.today()
            clock = t.perf_counter_ns
            x = elapsed()
        """) == [(6, "time.monotonic()", False), (8, "time.time()", False), (9, "time.perf_counter()", False),
                 (10, "datetime.datetime.now()", False), (11, "datetime.date.today()", False),
                 (12, "time.perf_counter_ns()", False)]


def test_seeding_from_the_clock_is_one_warning_at_the_seed():
    found = reads("""\
        import random, time
        from random import seed
        def main(s):
            random.seed()
            seed(time.time())
            random.seed(42)
            rng = random.Random(int(s.param("seed", 1)))
        """, "r.py")
    assert found == [(4, "random.seed()", True), (5, "seed(time.time())", True)]
    source = "import random\nrandom.seed()\n"
    (read,) = python_clock_reads(ast.parse(source), source, "r.py")
    assert read.text() == 'r.py:2: random.seed() makes every run different: seed from spinner.param("seed", 1) or a constant'


def test_generators_seeded_by_the_operating_system_are_warned_at_their_line():
    found = reads("""\
        import random
        import numpy as np
        from numpy.random import default_rng
        def main(s):
            a = np.random.default_rng()
            b = default_rng(None)
            c = np.random.RandomState()
            d = random.Random()
            e = random.SystemRandom(3)
            f = np.random.default_rng(seed=None)
            ok1 = np.random.default_rng(7)
            ok2 = default_rng(int(s.param("seed", 1)))
            ok3 = random.Random(42)
            ok4 = np.random.PCG64(1)
        """)
    assert found == [(5, "np.random.default_rng()", True), (6, "default_rng(None)", True),
                     (7, "np.random.RandomState()", True), (8, "random.Random()", True),
                     (9, "random.SystemRandom(3)", True), (10, "np.random.default_rng(seed=None)", True)]


def test_names_that_only_look_like_the_clock_are_not_warned():
    assert reads("""\
        import time
        def time_s(s):
            return s.get_time()
        def main(s):
            time.sleep(0.1)
            monotonic = s.get_time
            t = monotonic()
            perf_counter = 3
        """) == []


def test_a_controller_without_the_clock_and_the_example_have_no_such_warning(here, track):
    write("ok.py", """\
        def main(s):
            t0 = s.get_time()
            while True:
                s.get_image(s.line_row)
                s.set_speed_and_servo(0.5, 0.0 * (s.get_time() - t0))
        """)
    assert clock_lines(check_controller("ok.py", track=track, seconds=0.3).warnings) == []
    assert clock_lines(check_controller(EXAMPLES / "line_follower.py", track=track, seconds=0.3).warnings) == []


def test_many_places_are_capped():
    found = [ClockRead("a.c", n, "clock()") for n in range(1, 7)]
    texts = clock_warnings(found)
    assert len(texts) == SHOWN + 1
    assert texts[-1] == ("and 3 more places reading the computer's clock or seeding from it "
                         "(a.c:4, a.c:5, a.c:6)")


# -- C/C++ ----------------------------------------------------------------------------------
C_PROGRAM = """\
#include <stdlib.h>
#include <time.h>
#include <unistd.h>
#include "spinner.h"

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

int main(void) {
    srand(time(NULL));
    double last = now_s();
    for (;;) {
        double t = now_s(), dt = t - last;
        last = t;
        spinner_set_speed_and_servo(0.5, 0.0 * dt);
        usleep(10000);
    }
}
"""

CXX_PROGRAM = """\
#include <chrono>
#include <unistd.h>
#include "spinner.hpp"

int main() {
    Spinner s;
    auto last = std::chrono::steady_clock::now();
    for (;;) {
        auto now = std::chrono::steady_clock::now();
        double dt = std::chrono::duration<double>(now - last).count();
        last = now;
        s.setSpeedAndServo(0.5, 0.0 * dt);
        usleep(10000);
    }
}
"""


@needs_cc
def test_c_clock_gettime_and_srand_time_are_warned_at_their_lines(here):
    write("line_follower.c", C_PROGRAM)
    res = CliRunner().invoke(cli, ["check", "line_follower.c", "--seconds", "0.3"])
    assert f"  warning: line_follower.c:8: clock_gettime() {CLOCK}: {C_ADVICE}\n" in res.output
    assert ('  warning: line_follower.c:13: srand(time(NULL)) makes every run different: seed from '
            'spinner_param("seed", 1) or a constant\n') in res.output
    assert ": time() reads" not in res.output  # (srand's time: said once, as the seeding)
    res = CliRunner().invoke(cli, ["drive", "line_follower.c", "--time-limit", "0.3"])
    assert "outcome: timeout" in res.output, res.output
    assert res.stderr.count("line_follower.c:8: clock_gettime()") == 1
    assert res.output.index("line_follower.c:13: srand") < res.output.index("outcome: ")


@needs_cc
def test_the_warnings_come_from_the_build_cache_too(here):
    from simrunner.run.native import build_program

    write("line_follower.c", C_PROGRAM)
    first = build_program(["line_follower.c"])
    again = build_program(["line_follower.c"])
    assert again.cached and not first.cached
    assert again.clock_reads == first.clock_reads and len(first.clock_reads) == 2


@needs_cc
def test_a_users_header_is_named_a_systems_or_kits_is_not(here):
    from simrunner.run.native import build_program

    Path("inc").mkdir()
    write("inc/timing.h", """\
        #include <sys/time.h>
        static inline double wall_s(void) {
            struct timeval tv;
            gettimeofday(&tv, 0);
            return tv.tv_sec + tv.tv_usec * 1e-6;
        }
        """)
    write("main.c", """\
        #include "spinner.h"
        #include "timing.h"
        int main(void) { for (;;) spinner_set_speed_and_servo(0.5 + 0 * wall_s(), 0.0); }
        """)
    program = build_program(["main.c"], include_dirs=["inc"])
    assert [r.text().split(": ", 1)[0] for r in program.clock_reads] == ["inc/timing.h:4"]
    assert "gettimeofday()" in program.clock_reads[0].text()


@needs_cc
def test_cxx_steady_clock_now_is_warned(here, track):
    write("pid.cpp", CXX_PROGRAM)
    from simrunner.run.native import build_program

    report = check_controller(build_program(["pid.cpp"]), track=track, seconds=0.3)
    assert clock_lines(report.warnings) == [f"pid.cpp:7: std::chrono::steady_clock::now() {CLOCK}: {C_ADVICE}",
                                            f"pid.cpp:9: std::chrono::steady_clock::now() {CLOCK}: {C_ADVICE}"]


@needs_cc
@pytest.mark.parametrize("sources, kit", [
    (["line_follower.c"], None), (["firmware/main.c"], "tfc"), (["firmware/mbed/main.cpp"], "tfc-mbed"),
    (["firmware/s32k144/main.c"], "s32k144")])
def test_the_examples_and_the_kits_libraries_are_not_warned(sources, kit):
    from simrunner.run.native import build_program

    program = build_program([EXAMPLES / s for s in sources], kit=kit)
    assert program.clock_reads == ()


@needs_cc
def test_a_firmware_reading_the_clock_is_named_not_its_kit(here):
    from simrunner.run.native import build_program

    write("main.c", """\
        #include "TFC/TFC.h"
        #include <time.h>
        int main(void) {
            TFC_Init();
            clock_t start = clock();
            for (;;) TFC_SetServo(0, 0.0f * (float)(clock() - start));
        }
        """)
    program = build_program(["main.c"], kit="tfc")
    assert [(r.file, r.line, r.call) for r in program.clock_reads] == [("main.c", 5, "clock()"), ("main.c", 6, "clock()")]
