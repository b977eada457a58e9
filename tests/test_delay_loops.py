"""An empty counting loop in a team's C/C++ code (``for (i = 0; i < 100000 * x; i++);``) delays no
simulated time: ``simrunner check`` and ``drive`` say where, naming the kit's wait call
(simrunner.run.delayloops); a loop polling the kit, a loop with a body, the examples and the kits'
own sources are not warned."""
from __future__ import annotations

import os
import shutil
import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.run.delayloops import SHOWN, DelayLoop, delay_warnings, scan

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
NO_TIME = ("delays no simulated time here - the car's code runs in no time between the kit's calls (and -O2 "
           "removes a loop without volatile)")
needs_cc = pytest.mark.skipif(shutil.which("cc") is None and not os.environ.get("CC"),
                              reason="no C compiler (apt-get install build-essential)")

# a team's code (its forwardFull: full speed for a while, then stop), as on the board
FORWARD_FULL = """\
#include "derivative.h"
#include "TFC/TFC.h"

void forwardFull(int x)
{
    int i;
    TFC_HBRIDGE_ENABLE;
    TFC_SetMotorPWM(1, 1);
    for(i=0;i<100000*x;i++);
    TFC_SetMotorPWM(0, 0);
}

int main(void)
{
    TFC_Init();
    for (;;) {
        TFC_Task();
        forwardFull(5);
    }
    return 0;
}
"""


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


@pytest.fixture
def here(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def body(code: str) -> str:
    return textwrap.dedent(code)


@pytest.mark.parametrize("code, line, shown", [
    ("void f(int x) {\n  int i;\n  for(i=0;i<100000*x;i++);\n}", 3, "for ... i<100000*x ..."),
    ("void f(void) { for (volatile int i = 0; i < 50000; i++) {} }", 1, "for ... i < 50000 ..."),
    ("void f(int n) {\n  while (n--);\n}", 2, "while (n--)"),
    ("void f(void) { unsigned n = 5; while (n-- > 0) {} }", 1, "while (n-- > 0)"),
    ("#define N 1000\nvoid f(void) { int i = 0; while (i++ < N); }", 2, "while (i++ < N)"),
    ("void f(void) {\n  int n = 1000;\n  do {} while(--n);\n}", 3, "do {} while (--n)"),
    ("void f(void) { volatile long n = 1000; do ; while (n--); }", 1, "do {} while (n--)"),
    ("int i;\nvoid f(void) { for (i = 0; i < 1000; i += 2); }", 2, "for ... i < 1000 ..."),
    # a macro: at its definition line (its parameters are its locals)
    ("int i;\n#define DELAY(x) for (i = 0; i < (x); \\\n  i++);\nvoid f(void) { DELAY(10); }", 2,
     "for ... i < (x) ..."),
])
def test_empty_counting_loops_are_found_at_their_line(code, line, shown):
    assert scan(code) == [(line, shown)]


@pytest.mark.parametrize("code", [
    # polling the kit or an interrupt's flag: the kit lets time pass, the loop ends
    "void f(void) { while (!LineScanImageReady); }",
    "void f(void) { while (TFC_Ticker[0] < 20) {} }",
    "void f(void) { while (Dio_ReadChannel(SW2) == STD_LOW); }",
    "volatile int flag;\nvoid f(void) { while (!flag) {} }",
    "volatile int flag;\nvoid f(void) { int t = 100; while (!flag && t--); }",  # a timeout
    "int limit;\nvoid f(void) { int i; for (i = 0; i < limit; i++); }",  # another global
    # a body, a call, a dereference, an index
    "void f(void) { int i; for (i = 0; i < 10; i++) { g(i); } }",
    "void f(void) { int i; for (i = 0; i < 10; i++) g(i); }",
    "void f(void) { int i; for (i = 0; i < n(); i++); }",
    "void f(void) { int n = 3; do { g(); } while (--n); }",
    "#define G() do { g(); } while (0)",
    "void f(int *p) { while ((*p)--); }",
    "int f(const char *s) { int n = 0; while (s[n++]); return n; }",
    "void f(struct s *p) { while (p->n--); }",
    # forever, and what is not code
    "void f(void) { for (;;); while (1); }",
    "void f(void) { int i; /* for (i = 0; i < 10; i++); */ // while (i--);\n }",
    'void f(void) { puts("for (i = 0; i < 10; i++);"); }',
])
def test_polling_loops_and_loops_with_a_body_are_not_flagged(code):
    assert scan(code) == []


def test_the_warning_names_the_kits_wait_and_the_rest_are_counted():
    assert DelayLoop("motor.c", 42, "for ... i < 100000 * x ...", "tfc").text() == (
        f"motor.c:42: an empty counting loop (for ... i < 100000 * x ...) {NO_TIME}: wait with TFC_Delay_mS(ms), "
        "or run with --mcu-time measured --mcu-scale N")
    assert "wait with wait_ms(ms) / wait(s)," in DelayLoop("m.cpp", 1, "x", "tfc-mbed").text()
    assert "wait with OsIf_TimeDelay(ms)," in DelayLoop("m.c", 1, "x", "s32k144").text()
    assert "wait with spinner_sleep(seconds) / usleep(us)," in DelayLoop("m.c", 1, "x").text()
    loops = [DelayLoop("m.c", n, "while (n--)") for n in range(1, SHOWN + 3)]
    texts = delay_warnings(loops)
    assert len(texts) == SHOWN + 1
    assert texts[-1] == "and 2 more empty counting loops delaying no simulated time (m.c:4, m.c:5)"


@needs_cc
def test_a_teams_forward_full_is_warned_at_its_line_in_check_and_drive(here):
    Path("motor.c").write_text(FORWARD_FULL)
    warning = (f"motor.c:9: an empty counting loop (for ... i<100000*x ...) {NO_TIME}: wait with "
               "TFC_Delay_mS(ms), or run with --mcu-time measured --mcu-scale N")
    res = CliRunner().invoke(cli, ["check", "motor.c", "--kit", "tfc", "--seconds", "0.3"])
    assert f"  warning: {warning}\n" in res.output, res.output
    res = CliRunner().invoke(cli, ["drive", "motor.c", "--kit", "tfc", "--time-limit", "0.3"])
    assert "outcome: timeout" in res.output, res.output
    assert res.stderr.count(warning) == 1, res.stderr


@needs_cc
def test_found_once_per_build_and_kept_in_its_cache(here):
    from simrunner.run.native import build_program

    Path("inc").mkdir()
    Path("inc/delay.h").write_text("#define DELAY(n) do { volatile unsigned d_ = (n); while (d_--); } while (0)\n")
    Path("main.c").write_text(body("""\
        #include "spinner.h"
        #include "delay.h"
        int main(void) {
            for (;;) {
                spinner_set_speed_and_servo(0.5, 0.0);
                DELAY(1000000);
                spinner_sleep(0.01);
            }
        }
        """))
    first = build_program(["main.c"], include_dirs=["inc"])
    again = build_program(["main.c"], include_dirs=["inc"])
    assert again.cached and not first.cached
    assert again.delay_loops == first.delay_loops == (DelayLoop("inc/delay.h", 1, "while (d_--)"),)


@needs_cc
@pytest.mark.parametrize("sources, kit", [
    (["line_follower.c"], None), (["real_car_units.c"], None), (["camera_row_test.cpp"], None),
    (["pixy2_follower.cpp"], None), (["velocity_test.cpp"], None), (["firmware/twin/spinner_twin.c"], None),
    (["firmware/main.c"], "tfc"), (["firmware/isr/main.c"], "tfc"), (["firmware/mbed/main.cpp"], "tfc-mbed"),
    (["firmware/s32k144/main.c"], "s32k144")])
def test_the_examples_are_not_warned(sources, kit):
    from simrunner.run.native import build_program

    program = build_program([EXAMPLES / s for s in sources], include_dirs=[EXAMPLES / "firmware"], kit=kit)
    assert program.delay_loops == ()


@needs_cc
def test_a_loop_in_a_kits_own_sources_is_not_the_users(here, monkeypatch):
    from simrunner.run.native import build, build_program

    kits = here / "kits"
    (kits / "slow" / "include").mkdir(parents=True)
    (kits / "slow" / "include" / "slow.h").write_text(
        "void slow_wait(unsigned n);\nstatic inline void slow_spin(void) { for (volatile int i = 0; i < 9; i++); }\n")
    (kits / "slow" / "slow.c").write_text(
        '#include "slow.h"\nvoid slow_wait(unsigned n) { while (n--); }\n')
    monkeypatch.setattr(build, "KITS_DIR", kits)
    monkeypatch.setattr(build, "KITS", {**build.KITS, "slow": ("slow.c",)})
    Path("main.c").write_text(body("""\
        #include "spinner.h"
        #include "slow.h"
        int main(void) { for (;;) { slow_spin(); slow_wait(3); spinner_sleep(0.01); } }
        """))
    program = build_program(["main.c"], kit="slow")
    assert program.delay_loops == ()
    assert scan((kits / "slow" / "slow.c").read_text())  # (one there: it is the kit's)
