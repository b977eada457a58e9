"""C/C++ controllers (issue 11): build and cache, the run, faults with file:line, the
examples against their Python twins, the thesis's C++ programs, the CLI."""
from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from helpers import C_CTOR_ENDS, C_CTOR_FAULT, C_THREAD_FAULT, C_THREAD_OVERFLOW, CXX_THREAD_OVERFLOW

from simrunner.cli import main as cli
from simrunner.errors import ControllerFileError
from simrunner.telemetry.log import read_log, write_log
from simrunner.run.native import INCLUDE_DIR, NativeProgram, build_program, cflags, load_native
from simrunner.run.native.symbolize import parse_report
from simrunner.run.runner import drive, resolve_track
from vehicle.description import load_car

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and not os.environ.get("CC"),
                                reason="no C compiler (apt-get install build-essential)")

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"


@pytest.fixture(scope="module", autouse=True)
def cache(tmp_path_factory):
    """One build cache for the module (the host program is built once)."""
    old = os.environ.get("SIMRUNNER_CACHE_DIR")
    path = tmp_path_factory.mktemp("native-cache")
    os.environ["SIMRUNNER_CACHE_DIR"] = str(path)
    yield path
    if old is None:
        os.environ.pop("SIMRUNNER_CACHE_DIR", None)
    else:
        os.environ["SIMRUNNER_CACHE_DIR"] = old


@pytest.fixture(scope="module")
def track():
    return resolve_track(None, load_car(None))[0]


def isolated(*sources, **kw) -> NativeProgram:
    """The program built from ``sources``, to run in a child process (``--isolate``)."""
    return dataclasses.replace(build_program(list(sources), **kw), isolate=True)


def write(folder: Path, name: str, body: str) -> Path:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(body))
    return path


FAULTS_C = """\
#include <stdio.h>
#include <stdlib.h>
#include "spinner.h"
static volatile int zero = 0;
static int *volatile nowhere = NULL;
static int recurse(int n) { volatile char pad[256]; pad[0] = (char)n; return n < 0 ? 0 : recurse(n + 1) + pad[0]; }
static void fault(void) {
#if FAULT == 1
    *nowhere = 1;                                          /* line 9 */
#elif FAULT == 2
    abort();                                               /* line 11 */
#elif FAULT == 3
    printf("%d\\n", recurse(0));                            /* line 13 (recursion: 6) */
#elif FAULT == 4
    printf("%d\\n", 10 / zero);                             /* line 15 */
#elif FAULT == 5
    for (;;) {}                                            /* line 17 */
#elif FAULT == 6
    uint8_t row[128]; spinner_get_image(500, 1, row, 128); /* line 19 */
#elif FAULT == 7
    spinner_set_speed(0.0 / zero);                         /* line 21 */
#elif FAULT == 8
    exit(3);                                               /* line 23 */
#endif
}
int main(void) {
    uint8_t row[128];
    for (int i = 0; i < 10; i++) {
        spinner_get_image(60, 1, row, sizeof row);
        spinner_set_speed_and_servo(0.5, 0.0);
    }
    printf("before the fault\\n");
    fault();
    return 0;
}
"""


# -- build and cache --------------------------------------------------------------------------
def test_compile_error_is_the_compilers_file_line_exit_2_and_nothing_written(tmp_path):
    src = write(tmp_path, "bad.c", """\
        #include "spinner.h"
        int main(void) {
            spinner_set_speed(1.0)
            return 0;
        }
        """)
    csv = tmp_path / "run.csv"
    res = CliRunner().invoke(cli, ["drive", str(src), "--csv", str(csv)])
    assert res.exit_code == 2
    assert f"{src}:3:" in res.output and "error" in res.output and "Traceback" not in res.output
    assert not csv.exists()


def test_build_is_cached_by_content_and_headers_and_keeps_warnings(tmp_path):
    inc = write(tmp_path, "inc/gain.h", "#define GAIN 1.0\n")
    src = write(tmp_path, "c.c", """\
        #include "spinner.h"
        #include "gain.h"
        int main(void) { int unused; spinner_set_speed(GAIN); return 0; }
        """)
    first = build_program([src], include_dirs=[inc.parent])
    again = build_program([src], include_dirs=[inc.parent])
    assert not first.cached and again.cached and again.library == first.library
    assert "unused" in first.warnings and again.warnings == first.warnings
    inc.write_text("#define GAIN 2.0\n")  # an included header changed: rebuilt
    third = build_program([src], include_dirs=[inc.parent])
    assert not third.cached
    assert not build_program([src], include_dirs=[inc.parent], defines=["X=1"]).cached


@pytest.mark.parametrize("sources, kw, message", [
    (["missing.c"], {}, "no such controller file"),
    (["notes.txt"], {}, "expected C/C++ sources"),
    (["ok.c"], {"include_dirs": ["no-such-dir"]}, "no such include directory"),
    ([], {}, "no controller source"),
])
def test_bad_build_input_is_one_line(tmp_path, monkeypatch, sources, kw, message):
    monkeypatch.chdir(tmp_path)
    write(tmp_path, "ok.c", "int main(void) { return 0; }\n")
    write(tmp_path, "notes.txt", "x\n")
    with pytest.raises(ControllerFileError, match=re.escape(message)) as err:
        build_program(sources, **kw)
    assert "\n" not in str(err.value)


def test_no_compiler_is_one_line_naming_what_to_install(tmp_path, monkeypatch):
    monkeypatch.setenv("CC", "no-such-compiler-here")
    src = write(tmp_path, "c.c", "int main(void) { return 0; }\n")
    res = CliRunner().invoke(cli, ["drive", str(src)])
    assert res.exit_code == 2
    assert "build-essential" in res.output and len(res.output.strip().splitlines()) == 1


# -- runs -------------------------------------------------------------------------------------
def test_line_follower_c_logs_the_same_lap_as_the_python_one_and_is_deterministic(tmp_path, track):
    runs = {name: drive(EXAMPLES / name, track=track, csv=tmp_path / f"{name}.csv", seed=3)
            for name in ("line_follower.c", "line_follower.py")}
    c, py = runs["line_follower.c"], runs["line_follower.py"]
    assert c.outcome == py.outcome == "finished"
    assert abs(c.lap_times_s[0] - py.lap_times_s[0]) <= 0.02 * py.lap_times_s[0]
    # the same arithmetic on the same images: the same run log, number for number
    assert (tmp_path / "line_follower.c.csv").read_bytes() == (tmp_path / "line_follower.py.csv").read_bytes()
    again = drive(EXAMPLES / "line_follower.c", track=track, seed=3, csv=tmp_path / "again.csv")
    assert (tmp_path / "again.csv").read_bytes() == (tmp_path / "line_follower.c.csv").read_bytes()
    assert again.lap_times_s == c.lap_times_s


def test_without_recording_the_c_lap_is_the_python_lap_bit_for_bit(tmp_path, track):
    """No CSV, no video: the host sends no text, so each frame's requests are the queued
    command and the image call in one read (the bridge's short path)."""
    runs = {name: drive(EXAMPLES / name, track=track, seed=5)
            for name in ("line_follower.c", "line_follower.py")}
    for name, r in runs.items():
        assert r.outcome == "finished"
        write_log(r.log, tmp_path / f"{name}.csv", float_format="%.17g")
    assert (tmp_path / "line_follower.c.csv").read_bytes() == (tmp_path / "line_follower.py.csv").read_bytes()
    assert runs["line_follower.c"].lap_times_s == runs["line_follower.py"].lap_times_s


FRAMES_C = """\
#include <stdio.h>
#include "spinner.h"
int main(int argc, char **argv) {
    static uint8_t img[1 << 16];
    unsigned long long sum = 0;
    double gain = 0.0;
    for (int i = 0; i < 6; i++) {
        if (i == 3) {  /* a command and param(""): as many bytes as a frame's, not a frame */
            spinner_set_speed_and_servo(0.5, 0.0);
            gain = spinner_param("", 2.0);
        }
        spinner_set_speed_and_servo(0.5, 0.0);
        int line = i % 2 ? spinner_line_row() : -1;
        spinner_get_image(line, 1, img, sizeof img);
        int n = spinner_image_width() * (line < 0 ? spinner_image_height() : 1);
        for (int k = 0; k < n; k++) sum = sum * 31 + img[k];
    }
    printf("sum %llu gain %g\\n", sum, gain);
    if (argc > 1) spinner_set_speed_and_servo(0.4, 0.0);  /* a command queued, then the end */
    return 0;
}
"""

FRAMES_PY = """\
def main(s):
    total, gain = 0, 0.0
    for i in range(6):
        if i == 3:
            s.set_speed_and_servo(0.5, 0.0)
            gain = s.param("", 2.0)
        s.set_speed_and_servo(0.5, 0.0)
        for v in s.get_image(s.line_row if i % 2 else -1).ravel().tolist():
            total = (total * 31 + v) & (2 ** 64 - 1)
    print(f"sum {total} gain {gain:g}")
"""


def test_frames_whole_images_other_requests_and_the_end_as_from_python(tmp_path, track, capfd):
    """A camera frame in one switch (in process: the image handed in as it is, the next
    requests read in the host's buffer): whole images and rows arrive as a Python
    controller gets them, requests as long as a frame's that are not one are answered one
    by one, and the program may end right after a frame or after queueing a command."""
    src = write(tmp_path, "frames.c", FRAMES_C)
    py = write(tmp_path, "frames.py", FRAMES_PY)
    prog = build_program([src])
    runs = [drive(py, track=track), drive(prog, track=track),
            drive(load_native(prog, ("queue",)), track=track), drive(isolated(src), track=track),
            drive(load_native(isolated(src), ("queue",)), track=track)]
    assert [r.outcome for r in runs] == ["controller_returned"] * 5
    assert {r.frames for r in runs} == {7}  # frame 0 and the six images
    lines = [line for line in capfd.readouterr().out.splitlines() if line.startswith("sum ")]
    assert len(lines) == 5 and len(set(lines)) == 1 and lines[0].endswith(" gain 2")


def test_real_car_units_c_drives_as_the_python_one(tmp_path, track):
    c = drive(EXAMPLES / "real_car_units.c", track=track, csv=tmp_path / "c.csv")
    py = drive(EXAMPLES / "real_car_units.py", track=track, csv=tmp_path / "py.csv")
    assert c.outcome == py.outcome == "finished"
    assert (tmp_path / "c.csv").read_bytes() == (tmp_path / "py.csv").read_bytes()


def test_sleeps_wait_in_simulated_time_and_stdout_reaches_the_terminal(tmp_path, track, capfd):
    src = write(tmp_path, "sleeps.c", """\
        #include <stdio.h>
        #include <time.h>
        #include <unistd.h>
        #include "spinner.h"
        int main(void) {
            double t0 = spinner_get_time();
            usleep(100000);
            double t1 = spinner_get_time();
            struct timespec ts = {0, 50000000};
            nanosleep(&ts, NULL);
            double t2 = spinner_get_time();
            sleep(1);
            double t3 = spinner_get_time();
            spinner_sleep(0.25);
            printf("slept %.3f %.3f %.3f %.3f\\n", t1 - t0, t2 - t1, t3 - t2, spinner_get_time() - t3);
            fprintf(stderr, "to stderr\\n");
            return 0;
        }
        """)
    r = drive(src, track=track, time_limit_s=5)
    assert r.outcome == "controller_returned"
    out, err = capfd.readouterr()
    # each wait: its steps plus the one step of the get_time after it (dt 2 ms)
    assert "slept 0.102 0.052 1.002 0.252" in out
    assert "to stderr" in err
    assert r.sim_time_s == pytest.approx(1.41, abs=0.005)


@pytest.mark.parametrize("isolate", [False, True])
@pytest.mark.parametrize("lang", ["c", "cpp"])
def test_a_programs_own_function_or_global_named_as_libcs_is_its_own(tmp_path, track, capfd, isolate, lang):
    """A program's own ``step()`` ran libc's regex step(3) (a SIGSEGV in libc), its ``index()``
    libc's, its global ``daylight`` was libc's variable: a shared library's references went to the
    process's global scope first. Programs link with -Bsymbolic: its own, as on the MCU."""
    src = write(tmp_path, f"names.{lang}", """\
        #include <stdio.h>
        #include "spinner.h"
        int daylight = 7;
        int step(int n) { return n + 1; }
        double index(double x) { return 2 * x; }
        int main(void) {
            int n = 0;
            for (int i = 0; i < 5; i++) n = step(n);
            printf("step %d index %g daylight %d\\n", n, index(1.5), daylight);
            return 0;
        }
        """)
    program = isolated(src) if isolate else src
    r = drive(program, track=track, time_limit_s=1)
    assert r.outcome == "controller_returned", r.message
    assert "step 5 index 3 daylight 7" in capfd.readouterr().out


def test_param_comes_from_the_python_spinner(tmp_path, track, capfd):
    src = write(tmp_path, "param.c", """\
        #include <stdio.h>
        #include "spinner.h"
        int main(void) { printf("gain %g\\n", spinner_param("gain", 0.5)); return 0; }
        """)
    drive(src, track=track)  # no --param: the default
    assert "gain 0.5" in capfd.readouterr().out
    drive(src, track=track, params={"gain": 2.5})
    assert "gain 2.5" in capfd.readouterr().out


@pytest.mark.parametrize("value", ["abc", "x" * 1500])  # the refusal: shorter, longer than 1023 bytes
def test_a_refused_call_is_a_fault_at_its_c_line_with_the_simulators_words(tmp_path, track, value):
    src = write(tmp_path, "refused.c", """\
        #include <stdio.h>
        #include "spinner.h"
        int main(void) {
            uint8_t img[128 * 128];
            spinner_get_image(-1, 0, img, sizeof img);
            printf("gain %g\\n", spinner_param("gain", 0.5));
            return 0;
        }
        """)
    r = drive(src, track=track, params={"gain": value}, csv=tmp_path / "run.csv")
    assert r.outcome == "controller_error"
    assert r.message.startswith(f"{src}:6: param gain='{value[:20]}")
    if len(value) < 100:  # the whole text (a longer one is cut at 1023 bytes)
        assert r.message.endswith("expected a value of type float (the type of the default 0.5) (in main())")
    assert len(read_log(tmp_path / "run.csv")) == 2  # frame 0 and the one image


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity here")
def test_an_isolated_controller_process_is_kept_on_one_cpu_of_the_simulators(tmp_path, track, capfd):
    src = write(tmp_path, "cpu.c", """\
        #define _GNU_SOURCE
        #include <sched.h>
        #include <stdio.h>
        #include "spinner.h"
        int main(void) {
            uint8_t row[128];
            spinner_get_image(60, 0, row, sizeof row);
            cpu_set_t set;
            sched_getaffinity(0, sizeof set, &set);
            printf("cpus %d on %d\\n", CPU_COUNT(&set), sched_getcpu());
            return 0;
        }
        """)
    assert drive(isolated(src), track=track).outcome == "controller_returned"
    words = capfd.readouterr().out.split()
    assert words[:2] == ["cpus", "1"] and int(words[3]) in os.sched_getaffinity(0)


def test_multiple_sources_include_dirs_defines_and_exit_status(tmp_path, track, capfd):
    write(tmp_path, "inc/helper.h", "int helper(int);\n")
    write(tmp_path, "helper.cpp", 'extern "C" int helper(int x) { return x * SCALE; }\n')
    main_c = write(tmp_path, "main.c", """\
        #include <stdio.h>
        #include "helper.h"
        #include "spinner.h"
        int main(void) { printf("helper %d\\n", helper(21)); spinner_get_time(); return STATUS; }
        """)
    prog = build_program([main_c, tmp_path / "helper.cpp"], include_dirs=[tmp_path / "inc"],
                         defines=["SCALE=2", "STATUS=0"])
    assert drive(prog, track=track).outcome == "controller_returned"
    assert "helper 42" in capfd.readouterr().out
    failing = build_program([main_c, tmp_path / "helper.cpp"], include_dirs=[tmp_path / "inc"],
                            defines=["SCALE=2", "STATUS=3"])
    r = drive(failing, track=track)
    assert r.outcome == "controller_error" and "exited with status 3" in r.message


EXITS_C = """\
#include <stdlib.h>
#include <unistd.h>
#include "spinner.h"
static void leave(int status) {
#if HOW == 0
    exit(status);                                          /* line 6 */
#else
    _exit(status);                                         /* line 8 */
#endif
}
int main(void) {
    static uint8_t row[1024];
    for (int i = 0; ; i++) {
        spinner_set_speed_and_servo(1.0, 0.0);
        spinner_get_image(spinner_line_row(), 1, row, sizeof row);
        if (i == 10) leave(STATUS);
    }
}
"""


@pytest.mark.parametrize("how, status, outcome, said", [
    (0, 0, "controller_returned", ("the controller called exit(0) at ", "exits.c:6")),
    (0, 5, "controller_error", ("the controller called exit(5) at ", "exits.c:6")),
    (1, -2, "controller_error", ("the controller called _exit(-2) at ", "exits.c:8")),
])
@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_an_exit_names_its_call_and_line_as_sys_exit_is_named(tmp_path, track, how, status, outcome, said,
                                                             isolate):
    """exit/_exit in a C program: the outcome says which call, its status and where (as a Python
    controller's ``sys.exit`` is told), in the simulator's process as isolated; ``_exit(-2)`` is
    the status 254 a process ends with, not a signal (in process it read "killed by SIGINT")."""
    src = write(tmp_path, "exits.c", EXITS_C)
    prog = dataclasses.replace(build_program([src], defines=[f"HOW={how}", f"STATUS={status}"]), isolate=isolate)
    r = drive(prog, track=track, csv=tmp_path / "run.csv")
    assert r.outcome == outcome and r.message.startswith(said[0]) and r.message.endswith(said[1]), r.message
    assert len(read_log(tmp_path / "run.csv")) >= 10  # the run so far is kept


EXIT_HANDLERS = {
    "handler.c": """\
#include <stdlib.h>
#include "spinner.h"
static void bye(void) { exit(5); }                     /* line 3 */
int main(void) {
    static uint8_t row[1024];
    atexit(bye);
    for (int i = 0; ; i++) {
        spinner_get_image(spinner_line_row(), 1, row, sizeof row);
        if (i == 10) exit(3);
    }
}
""",
    "dtor.cpp": """\
#include <cstdlib>
#include "spinner.h"
struct Last { ~Last() { std::exit(11); } };            // line 3
static Last last;
int main() {
    static uint8_t row[1024];
    for (int i = 0; i < 10; i++) spinner_get_image(spinner_line_row(), 1, row, sizeof row);
    return 0;
}
""",
    "seventy_two.c": """\
#include <stdlib.h>
#include "spinner.h"
int main(void) {
    static uint8_t row[1024];
    spinner_get_image(spinner_line_row(), 1, row, sizeof row);
    exit(72);                                          /* line 6 */
}
""",
}


@pytest.mark.parametrize("name, said", [
    ("handler.c", ("the controller called exit(5) at ", "handler.c:3")),
    ("dtor.cpp", ("the controller called exit(11) at ", "dtor.cpp:3")),
    ("seventy_two.c", ("the controller called exit(72) at ", "seventy_two.c:6")),
])
@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_the_exit_named_is_the_one_the_program_ends_with(tmp_path, track, name, said, isolate):
    """An exit in an exit handler (an atexit handler after main's exit(3), a C++ static
    destructor) is the status the program ends with and the call named, in process as isolated
    (in process it read 'exit(3) at handler.c:10' for status 5, and a destructor's exit had no
    line); a program's own exit(72) is not the host's 'no main() function defined'."""
    src = write(tmp_path, name, EXIT_HANDLERS[name])
    prog = dataclasses.replace(build_program([src]), isolate=isolate)
    r = drive(prog, track=track)
    assert r.outcome == "controller_error" and r.message.startswith(said[0]), r.message
    assert r.message.endswith("/" + said[1]), r.message


THREAD_EXIT_C = """\
#include <stdlib.h>
#include <unistd.h>
#include <pthread.h>
#include "spinner.h"
static void *ends(void *arg) {
    (void)arg;
    if (QUICK) _exit(9);
    exit(8);
}
int main(void) {
    static uint8_t row[1024];
    pthread_t t;
    for (int i = 0; ; i++) {
        spinner_set_speed_and_servo(1.0, 0.0);
        spinner_get_image(spinner_line_row(), 1, row, sizeof row);
        if (i == 5) pthread_create(&t, NULL, ends, NULL);
    }
}
"""


@pytest.mark.parametrize("quick, status", [(0, 8), (1, 9)])
@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_an_exit_from_another_thread_ends_the_program_with_its_status(tmp_path, track, quick, status, isolate):
    """exit/_exit called by a thread the program started ends the program with that status, as
    it ends a process (in process: at main()'s next waiting call); in process it switched main()'s
    stack from the other thread and crashed the simulator's process (SIGSEGV: a batch's
    worker_died)."""
    src = write(tmp_path, "thread_exit.c", THREAD_EXIT_C)
    prog = dataclasses.replace(build_program([src], defines=[f"QUICK={quick}"]), isolate=isolate)
    r = drive(prog, track=track, csv=tmp_path / "run.csv")
    assert r.outcome == "controller_error" and r.message.endswith(f"the controller exited with status {status}"), \
        r.message
    assert len(read_log(tmp_path / "run.csv")) >= 5  # the run so far is kept


def test_a_prebuilt_shared_library_runs(tmp_path, track, capfd):
    src = write(tmp_path, "pre.c", """\
        #include <stdio.h>
        #include "spinner.h"
        int main(void) { uint8_t img[128 * 128];
            printf("bytes %zu\\n", spinner_get_image(-1, 0, img, sizeof img)); return 0; }
        """)
    lib = tmp_path / "pre.so"
    subprocess.run(["cc", "-shared", "-fPIC", "-g", cflags(), str(src), "-o", str(lib)], check=True)
    r = drive(lib, track=track)
    assert r.outcome == "controller_returned" and "bytes 16384" in capfd.readouterr().out



PREBUILT_EXIT_C = """\
#include <stdlib.h>
#include "spinner.h"
static int frames;
void tick(void) {
    if (++frames == 10) EXIT(3);                         /* line 5 */
}
int main(void) {
    for (;;) { spinner_set_speed(0.5f); spinner_sleep(0.01f); tick(); }
}
"""


@pytest.mark.parametrize("call", ["exit", "_exit"])
@pytest.mark.parametrize("build", ["-g", "no -g", "stripped"])
def test_a_prebuilt_librarys_exit_says_where_it_can(tmp_path, monkeypatch, call, build):
    """exit(3) in a prebuilt library (not linked by simrunner: its exit was libc's, unnoted) said
    only 'pre: the controller exited with status 3', even with debug information. Now the host
    program's own exit notes the call: its file:line with -g; without, the function and offset from
    the symbol table and what to do for a line, in the same message."""
    monkeypatch.chdir(tmp_path)
    src = write(tmp_path, "pre.c", PREBUILT_EXIT_C)
    lib = tmp_path / "pre.so"
    subprocess.run(["cc", "-shared", "-fPIC", "-O0", *(["-g"] if build == "-g" else []), f"-DEXIT={call}",
                    cflags(), str(src), "-o", str(lib)], check=True)
    if build == "stripped":
        subprocess.run(["strip", str(lib)], check=True)
    r = drive(build_program([str(lib)]), track="floor", time_limit_s=5.0)
    assert r.outcome == "controller_error"
    if build == "-g":
        assert r.message == f"the controller called {call}(3) at pre.c:5", r.message
    else:
        assert re.fullmatch(rf"the controller called {call}\(3\) at pre\.so\+0x[0-9a-f]+ \(in tick\(\); no debug "
                            r"information in pre\.so: build it with -g for its file:line\)", r.message), r.message

# -- faults -----------------------------------------------------------------------------------
@pytest.mark.parametrize("fault, outcome, line, words", [
    (1, "controller_error", 9, "SIGSEGV"),
    (2, "controller_error", 11, "SIGABRT"),
    (3, "controller_error", 6, "stack overflow"),
    (4, "controller_error", 15, "SIGFPE"),
    (5, "stalled", 17, "stalled"),
    (6, "controller_error", 19, "spinner_get_image(line=500)"),
    (7, "controller_error", 21, "spinner_set_speed(speed="),
    (8, "controller_error", 23, "the controller called exit(3) at"),
])
@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_faults_name_the_c_line_and_keep_the_run_so_far(tmp_path, track, capfd, fault, outcome,
                                                        line, words, isolate):
    src = write(tmp_path, "faults.c", FAULTS_C)
    prog = build_program([src], defines=[f"FAULT={fault}"])
    prog = dataclasses.replace(prog, isolate=isolate)
    r = drive(prog, track=track, csv=tmp_path / "run.csv", wall_limit_s=0.5)
    assert r.outcome == outcome
    assert words in r.message
    if line is not None:
        assert f"faults.c:{line}" in r.message
        if outcome == "controller_error":
            assert f"faults.c:{line}" in r.error.traceback_text
    # the ten frames before the fault are recorded and written
    assert len(read_log(tmp_path / "run.csv")) >= 11
    assert "before the fault" in capfd.readouterr().out
    # the simulator survives: the next run is fine
    assert drive(EXAMPLES / "line_follower.c", track=track, time_limit_s=0.5).outcome == "timeout"


@pytest.mark.parametrize("fault, outcome, line", [(1, "controller_error", 9), (5, "stalled", 17)])
@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_slow_symboliser_neither_loses_the_line_nor_steps_the_simulation(tmp_path, track,
                                                                          monkeypatch, fault, outcome, line,
                                                                          isolate):
    """addr2line that closes its output and lingers before it exits: subprocess's bounded wait
    for it polls with time.sleep, which must be the real sleep there (the simulator's code),
    not the run's simulated one (that raised RunFinished after a stall, losing the line, and
    advanced the physics after a fault)."""
    src = write(tmp_path, "faults.c", FAULTS_C)
    prog = dataclasses.replace(build_program([src], defines=[f"FAULT={fault}"]), isolate=isolate)
    before = drive(prog, track=track, wall_limit_s=0.5)
    real = shutil.which("addr2line")
    if real is None:
        pytest.skip("no addr2line (binutils)")
    slow = write(tmp_path, "bin/addr2line", f"""\
        #!/bin/sh
        {real} "$@"
        exec >&- 2>&-
        sleep 0.3
        """)
    slow.chmod(0o755)
    monkeypatch.setenv("PATH", f"{slow.parent}{os.pathsep}{os.environ['PATH']}")
    r = drive(prog, track=track, wall_limit_s=0.5)
    assert r.outcome == before.outcome == outcome
    assert f"faults.c:{line}" in r.message and f"faults.c:{line}" in before.message
    assert r.sim_time_s == before.sim_time_s and r.frames == before.frames


def test_a_fault_in_a_function_of_a_header_names_the_header(tmp_path, track):
    """A function the program's header defines, not inlined, that faults: the report names the
    header's file and line (binutils' addr2line once named the .c file at the header's line)."""
    write(tmp_path, "util.h", """\
        static void __attribute__((noinline)) poke(int *p) {
            *p = 1;
        }
        """)
    src = write(tmp_path, "prog.c", """\
        #include "util.h"
        #include "spinner.h"
        int main(void) {
            spinner_get_time();
            poke(0);
            return 0;
        }
        """)
    r = drive(build_program([src]), track=track, time_limit_s=1.0)
    assert r.outcome == "controller_error"
    assert "util.h:2: SIGSEGV: segmentation fault (in poke())" in r.message, r.message
    assert "prog.c:5" in r.error.traceback_text
    # a library built elsewhere with the compiler's default debug info (GCC 12: DWARF 5, whose line
    # table binutils 2.40's addr2line misreads): the line table's own file name is taken
    lib = tmp_path / "prebuilt.so"
    subprocess.run(["cc", "-shared", "-fPIC", "-g", "-O0", cflags(), str(src), "-o", str(lib)], check=True)
    r = drive(lib, track=track, time_limit_s=1.0)
    assert "util.h:2: SIGSEGV: segmentation fault (in poke())" in r.message, r.message


def test_fault_report_parsing_table():
    """The host's report format: handler frames dropped, frames below main cut."""
    host, lib = "/x/spinner_host", "/x/ctrl.so"
    report = "\n".join([
        "signal 11", "message ", "pc 0x5010",
        f"frame 0x1000 0x1000 {host}\tfault_report", f"frame 0x2000 0x2000 {host}\ton_fault",
        "frame 0x3000 0x3000 /lib/libc.so.6\t", f"frame 0x5010 0x10 {lib}\tcrash",
        f"frame 0x5020 0x20 {lib}\tmain", f"frame 0x6000 0x6000 {host}\tmain",
        "frame 0x7000 0x7000 /lib/libc.so.6\t__libc_start_main"])
    fault = parse_report(report, {lib}, host)
    assert fault.signal == 11
    assert [f.function for f in fault.frames] == ["crash", "main"]  # no debug info: names only
    misuse = parse_report("\n".join(["signal 0", "message spinner_sleep(seconds=-1): bad",
                                     f"frame 0x1 0x1 {host}\tfault_report",
                                     f"frame 0x2 0x2 {host}\tspinner_sleep",
                                     f"frame 0x3 0x30 {lib}\tloop"]), {lib}, host)
    assert misuse.message.startswith("spinner_sleep") and [f.function for f in misuse.frames] == ["loop"]


# -- C++ and the thesis's programs --------------------------------------------------------------
def test_thesis_camera_row_program_runs_unchanged(tmp_path, track):
    text = (EXAMPLES / "camera_row_test.cpp").read_text()
    assert 's.addData({"image_row:" + std::to_string(i)});' in text and "usleep(100000);" in text
    r = drive(EXAMPLES / "camera_row_test.cpp", track=track, csv=tmp_path / "rows.csv")
    assert r.outcome == "controller_returned"
    assert r.sim_time_s == pytest.approx(128 * 0.12)  # a frame + 0.1 s per row, as in Python
    texts = read_log(tmp_path / "rows.csv").data_text
    assert "image_row:0" in texts and "image_row:127" in texts


def test_thesis_velocity_program_runs_unchanged(tmp_path, track, capfd):
    text = (EXAMPLES / "velocity_test.cpp").read_text()
    assert "auto [sx, sy, sz] = s.getPosition();" in text and "while(s.getTime() - time < 1){}" in text
    r = drive(EXAMPLES / "velocity_test.cpp", track=track)
    assert r.outcome == "controller_returned"
    out = capfd.readouterr().out
    dist = [float(line.split("distance:")[1]) for line in out.splitlines() if "distance:" in line]
    # speed units of 0.1 m/s held 2 s, scaled by the thesis's 0.774193548
    np.testing.assert_allclose(dist, [0.2 * 0.774193548 * k for k in (1, 2, 3)], rtol=0.03)


def test_spinner_hpp_image_type_and_norms(tmp_path, track, capfd):
    src = write(tmp_path, "img.cpp", """\
        #include "spinner.hpp"
        int main() {
            Spinner s(std::nullopt, [](float v, float) { return v * 10; },
                      [](float, float a) { return -a / 512 * 0.4f; });
            auto row = s.getImage(60, false);
            auto img = s.getImage();
            s.addData(row);
            s.addNoise(img);
            s.setSpeedAndServo(1.0, -512);
            auto [x, y, z] = s.getPosition();
            for (int i = 0; i < 20; i++) s.getImage(60);
            std::cout << row.rows << "x" << row.cols << " " << img.rows << "x" << img.cols
                      << " mid " << int(row.at<uint8_t>(0, 64)) << " data " << int(row.data[64])
                      << " speed " << (s.getSpeed() > 2 ? "denormed" : "raw") << std::endl;
            (void)x; (void)y; (void)z;
            return 0;
        }
        """)
    r = drive(src, track=track, csv=tmp_path / "c.csv")
    assert r.outcome == "controller_returned", r.message
    out = capfd.readouterr().out
    assert "1x128 128x128 mid " in out and "speed denormed" in out
    mid = int(out.split(" mid ")[1].split()[0])
    assert mid > 128 and f"data {mid}" in out  # the lane is white ahead
    log = read_log(tmp_path / "c.csv")
    assert log.steer_cmd_rad[-1] == pytest.approx(0.4)  # -512 = full left through turn_norm


# A stand-in for OpenCV's cv::Mat (not installed here): the members spinner.hpp uses, with
# OpenCV's names and semantics - a region shares the pixels and keeps its parent's row step,
# copyTo into a Mat of the same size and type writes into its pixels. The program below ran
# the same against OpenCV 4.6's own headers and libopencv_core.
CV_MAT_STAND_IN = """\
    #pragma once
    #include <algorithm>
    #include <cstddef>
    #include <memory>
    #include <vector>
    typedef unsigned char uchar;
    #define CV_8UC1 0
    namespace cv {
    struct Rect {
        int x, y, width, height;
        Rect(int x_, int y_, int w_, int h_) : x(x_), y(y_), width(w_), height(h_) {}
    };
    class Mat {
      public:
        int rows = 0, cols = 0;
        uchar *data = nullptr;
        std::size_t step = 0;
        Mat() = default;
        Mat(int r, int c, int type)
            : rows(r), cols(c), step(std::size_t(c)),
              pixels_(std::make_shared<std::vector<uchar>>(std::size_t(r) * c)) {
            (void)type;
            data = pixels_->data();
        }
        Mat operator()(const Rect &roi) const {
            Mat m = *this;
            m.rows = roi.height;
            m.cols = roi.width;
            m.data = data + roi.y * step + roi.x;
            return m;
        }
        bool isContinuous() const { return rows == 1 || step == std::size_t(cols); }
        int type() const { return CV_8UC1; }
        uchar *ptr(int r = 0) { return data + r * step; }
        const uchar *ptr(int r = 0) const { return data + r * step; }
        template <typename T> T &at(int r, int c) { return reinterpret_cast<T *>(ptr(r))[c]; }
        Mat clone() const {
            Mat m(rows, cols, CV_8UC1);
            for (int r = 0; r < rows; r++) std::copy(ptr(r), ptr(r) + cols, m.ptr(r));
            return m;
        }
        void copyTo(Mat &dst) const {  // dst: the same size (a region of a larger Mat too)
            for (int r = 0; r < rows; r++) std::copy(ptr(r), ptr(r) + cols, dst.ptr(r));
        }
      private:
        std::shared_ptr<std::vector<uchar>> pixels_;
    };
    }  // namespace cv
    """


def test_spinner_hpp_opencv_branch_noise_on_a_region_stays_in_it(tmp_path, track, capfd):
    write(tmp_path, "cv/opencv2/core.hpp", CV_MAT_STAND_IN)
    src = write(tmp_path, "roi.cpp", """\
        #include <type_traits>
        #include "spinner.hpp"
        static_assert(std::is_same<spinner::Image, cv::Mat>::value, "the OpenCV branch");
        int main() {
            Spinner s;
            cv::Mat row = s.getImage(60, false);
            cv::Mat img = s.getImage(-1, false);
            cv::Mat before = img.clone();
            cv::Mat roi = img(cv::Rect(10, 50, 100, 20));  // columns 10..109 of rows 50..69
            s.addData(roi);
            s.addNoise(roi);
            int outside = 0, inside = 0;
            for (int r = 0; r < img.rows; r++)
                for (int c = 0; c < img.cols; c++)
                    if (img.at<uchar>(r, c) != before.at<uchar>(r, c))
                        (r >= 50 && r < 70 && c >= 10 && c < 110 ? inside : outside)++;
            std::cout << "row " << row.rows << "x" << row.cols << " mid " << int(row.at<uchar>(0, 64))
                      << " continuous " << roi.isContinuous() << " outside " << outside
                      << " inside " << inside << std::endl;
            return 0;
        }
        """)
    prog = build_program([src], include_dirs=[tmp_path / "cv"])
    assert prog.warnings == ""
    r = drive(prog, track=track)
    assert r.outcome == "controller_returned", r.message
    out = capfd.readouterr().out
    assert "row 1x128 mid " in out and "continuous 0 outside 0 inside " in out
    mid, inside = int(out.split(" mid ")[1].split()[0]), int(out.split(" inside ")[1].split()[0])
    assert mid > 128  # the lane is white ahead
    assert inside > 1000  # of the region's 2000 pixels, most got noise; none outside it


def test_headers_compile_cleanly_with_strict_warnings(tmp_path):
    src = write(tmp_path, "strict.cpp", '#include "spinner.hpp"\nint main() { Spinner s; return 0; }\n')
    c_src = write(tmp_path, "strict.c", '#include "spinner.h"\nint main(void) { return 0; }\n')
    for compiler, path in (("c++", src), ("cc", c_src)):
        proc = subprocess.run([compiler, "-fsyntax-only", "-Wall", "-Wextra", "-pedantic",
                               f"-I{INCLUDE_DIR}", str(path)], capture_output=True, text=True)
        assert proc.returncode == 0 and proc.stderr == "", proc.stderr


def test_cli_prints_the_include_dir_and_cflags():
    runner = CliRunner()
    inc = runner.invoke(cli, ["include-dir"])
    assert inc.exit_code == 0 and (Path(inc.output.strip()) / "spinner.h").is_file()
    flags = runner.invoke(cli, ["cflags"])
    assert flags.output.strip() == f"-I{inc.output.strip()}"


def test_sources_without_main_are_bad_input_and_nothing_is_written(tmp_path, track):
    src = write(tmp_path, "nomain.c", "int helper(void) { return 1; }\n")
    with pytest.raises(ControllerFileError, match=r"nomain\.c: no main\(\) function defined"):
        drive(src, track=track, csv=tmp_path / "run.csv")
    assert not (tmp_path / "run.csv").exists()


# -- in the simulator's process (the default) and --isolate -------------------------------------
def test_every_in_process_run_starts_from_fresh_globals(tmp_path, track, capfd):
    """A static, and a C++ inline variable (GCC makes those process-wide unless told not to):
    each run counts from 0 - a new program each time, or one controller run twice."""
    src = write(tmp_path, "count.cpp", """\
        #include <cstdio>
        #include "spinner.hpp"
        inline int shared_count = 0;
        static int file_count;
        int main() { Spinner s; s.getTime(); std::printf("count %d %d\\n", ++shared_count, ++file_count); }
        """)
    prog = build_program([src])
    ctrl = load_native(prog)
    for controller in (prog, prog, ctrl, ctrl):
        assert drive(controller, track=track).outcome == "controller_returned"
    assert capfd.readouterr().out.split("\n")[:4] == ["count 1 1"] * 4


def test_after_an_in_process_run_the_signals_are_the_simulators_again(tmp_path):
    """The run's handlers (faults in the controller's code) are removed after it: a crash of
    the simulator itself later still reaches Python's faulthandler."""
    src = write(tmp_path, "ok.c", '#include "spinner.h"\nint main(void) { spinner_get_time(); return 0; }\n')
    code = textwrap.dedent(f"""\
        import faulthandler, sys
        faulthandler.enable()
        from simrunner.run.runner import drive
        print(drive({str(src)!r}, time_limit_s=1.0).outcome, flush=True)
        from simrunner.run.native import load_native
        load_native([{str(src)!r}]).close()  # (the handlers of an open too)
        faulthandler._sigsegv()
        """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.stdout.strip() == "controller_returned"
    assert done.returncode != 0 and "Fatal Python error: Segmentation fault" in done.stderr


def test_a_program_runs_in_the_simulators_process_unless_isolated(tmp_path, track, capfd):
    src = write(tmp_path, "pid.c", """\
        #include <stdio.h>
        #include <unistd.h>
        #include "spinner.h"
        int main(void) { spinner_get_time(); printf("pid %d\\n", (int)getpid()); return 0; }
        """)
    for prog in (build_program([src]), isolated(src)):
        assert drive(prog, track=track).outcome == "controller_returned"
    pids = [int(line.split()[1]) for line in capfd.readouterr().out.splitlines() if line.startswith("pid")]
    assert pids[0] == os.getpid() != pids[1]


def test_cli_isolate_runs_a_c_controller_and_refuses_python(tmp_path):
    runner = CliRunner()
    res = runner.invoke(cli, ["drive", str(EXAMPLES / "line_follower.c"), "--isolate",
                              "--time-limit", "1", "--summary", str(tmp_path / "s.json")])
    assert res.exit_code == 1 and "outcome: timeout" in res.output  # a lap not completed
    res = runner.invoke(cli, ["drive", str(EXAMPLES / "line_follower.py"), "--isolate"])
    assert res.exit_code == 2
    assert res.output.strip() == f"simrunner: {EXAMPLES / 'line_follower.py'}: --isolate is for C/C++ controllers"


def test_two_runs_in_threads_at_once_both_run_and_log_what_one_alone_logs(tmp_path, track):
    """One in-process run at a time per process: a second one at the same time (another
    thread) runs in a child process, with the same numbers."""
    import threading

    prog = build_program([EXAMPLES / "line_follower.c"])
    alone = drive(prog, track=track, time_limit_s=2.0, csv=tmp_path / "alone.csv")
    results = {}

    def run(k: int) -> None:
        results[k] = drive(prog, track=track, time_limit_s=2.0, csv=tmp_path / f"{k}.csv")

    threads = [threading.Thread(target=run, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert [results[k].outcome for k in range(2)] == [alone.outcome] * 2 == ["timeout"] * 2
    for k in range(2):
        assert (tmp_path / f"{k}.csv").read_bytes() == (tmp_path / "alone.csv").read_bytes()


def test_while_the_in_process_host_is_taken_a_run_goes_to_a_child_process(tmp_path, track, capfd):
    import ctypes

    from simrunner.run.native.inproc import OpenedProgram, host_library

    src = write(tmp_path, "pid.c", """\
        #include <stdio.h>
        #include <unistd.h>
        #include "spinner.h"
        int main(void) { spinner_get_time(); printf("pid %d\\n", (int)getpid()); return 0; }
        """)
    prog = build_program([src])
    _, api = host_library()
    other = OpenedProgram(api, prog)  # another run holds the host (as from another thread)
    argv = (ctypes.c_char_p * 2)(b"other", None)
    assert api.spinner_inproc_start(other.handle, 1, argv, 0.0, -1) == 0
    try:
        assert drive(prog, track=track).outcome == "controller_returned"
    finally:
        api.spinner_inproc_finish()
        other.close()
    assert drive(prog, track=track).outcome == "controller_returned"
    pids = [int(line.split()[1]) for line in capfd.readouterr().out.splitlines() if line.startswith("pid")]
    assert pids[0] != os.getpid() == pids[1]


def test_calls_after_the_run_from_atexit_handlers_return_at_once(tmp_path, track, capfd):
    """atexit handlers run when the program's library is unloaded, outside any run: their
    Spinner calls return at once (the last values) instead of switching to nowhere."""
    import gc

    src = write(tmp_path, "bye.c", """\
        #include <stdio.h>
        #include <stdlib.h>
        #include "spinner.h"
        static void bye(void) { printf("bye %.3f\\n", spinner_get_time()); fflush(stdout); }
        int main(void) { atexit(bye); spinner_sleep(0.1); spinner_get_time(); return 0; }
        """)
    prog = build_program([src])
    for _ in range(2):
        assert drive(prog, track=track).outcome == "controller_returned"
    gc.collect()
    assert drive(EXAMPLES / "line_follower.c", track=track, time_limit_s=0.2).outcome == "timeout"
    assert capfd.readouterr().out.count("bye 0.10") == 2


def test_exposure_from_c_and_cpp_sets_the_line_cameras_frame_period(tmp_path, track, capfd):
    car = load_car(None)
    toml = tmp_path / "car.toml"
    car.replace(camera=dataclasses.replace(car.camera, model="linescan")).save(toml)
    src = write(tmp_path, "exposure.c", """\
        #include <stdio.h>
        #include "spinner.h"
        int main(void) {
            uint8_t row[128];
            spinner_get_image(60, 1, row, sizeof row);
            double t0 = spinner_get_time();
            spinner_set_exposure(0.0045);
            spinner_get_image(60, 1, row, sizeof row);
            spinner_get_image(60, 1, row, sizeof row);
            printf("exposure %g period %.4f\\n", spinner_get_exposure(), spinner_get_time() - t0);
            spinner_set_exposure(-1.0);
            return 0;
        }
        """)
    r = drive(src, track=track, car=toml)
    out = capfd.readouterr().out
    # t0 is one step after frame 1 (20 ms); then frames at 20 + 5 and 25 + 5 ms, one step more
    assert "exposure 0.0045 period 0.0100" in out
    assert r.outcome == "controller_error"
    assert "set_exposure(seconds=-1.0): expected 1e-05 to 1 s" in r.message
    assert "exposure.c:11" in r.error.traceback_text
    cpp = write(tmp_path, "exposure.cpp", """\
        #include <cstdio>
        #include "spinner.hpp"
        int main() {
            Spinner s;
            s.setExposure(0.0095);
            s.getImage(60);
            std::printf("cpp exposure %g\\n", s.getExposure());
            return 0;
        }
        """)
    drive(cpp, track=track, car=toml)
    assert "cpp exposure 0.0095" in capfd.readouterr().out


FREE_RUNNING_CPP = """\
    #include <cstdio>
    #include "spinner.hpp"
    int main() {
        Spinner s;
        s.cameraFreeRunning();
        s.setExposure(0.0095);
        s.getImage(s.lineRow());
        double t0 = s.getTime();
        int frames = 0;
        while (s.getTime() - t0 < 2.0 - 1e-9) {
            s.getImage(s.lineRow());
            frames++;
        }
        std::printf("frames %d period %.6f\\n", frames, (s.getTime() - t0) / frames);
        std::fflush(stdout);
        return 0;
    }
    """


def _free_running_py(s):  # FREE_RUNNING_CPP through Python's camelCase names
    s.cameraFreeRunning()
    s.setExposure(0.0095)
    s.getImage(s.line_row)
    t0, frames = s.getTime(), 0
    while s.getTime() - t0 < 2.0 - 1e-9:
        s.getImage(s.line_row)
        frames += 1
    print(f"frames {frames} period {(s.getTime() - t0) / frames:.6f}", flush=True)


@pytest.mark.parametrize("lang", ["c++", "c++ isolated", "python"])
def test_camera_free_running_from_cpp_gives_frames_one_exposure_apart(tmp_path, track, capfd, lang):
    """spinner.hpp's cameraFreeRunning (spinner_camera_free_running; Python's camelCase alias
    too): a linescan camera's frames are then one exposure apart, 211 in 2 s at 9.5 ms (without
    it 200, exposure + read-out: tests/test_kit_tfc.py). Before, spinner.hpp had no such member
    (the program did not compile)."""
    if lang == "python":
        prog = _free_running_py
    else:
        prog = build_program([str(write(tmp_path, "free.cpp", FREE_RUNNING_CPP))])
        prog = dataclasses.replace(prog, isolate=lang.endswith("isolated"))
    r = drive(prog, track=track, time_limit_s=3.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    frames, period = int(out.split("frames ")[1].split()[0]), float(out.split(" period ")[1].split()[0])
    assert frames == 211 and period == pytest.approx(0.0095, abs=2e-5), out  # (frames on 2-ms steps)


NEXT_FRAME_CPP = """\
    #include <cstdio>
    #include "spinner.hpp"
    int main() {
        Spinner s;
        s.cameraFreeRunning();
        s.setExposure(0.010);
        s.getImage(s.lineRow());
        double t = s.getTime();
        s.sleep(0.004);
        s.setExposureNextFrame(0.020);
        for (int i = 0; i < 3; i++) {
            s.getImage(s.lineRow());
            double now = s.getTime();  // (a getTime lets a physics step pass: one a frame)
            std::printf("period %.4f\\n", now - t);
            t = now;
        }
        std::fflush(stdout);
        return 0;
    }
    """


@pytest.mark.parametrize("isolate", [False, True])
def test_set_exposure_next_frame_from_cpp_loads_as_the_frame_in_progress_ends(tmp_path, capfd, isolate):
    """spinner.hpp's setExposureNextFrame (spinner_set_exposure_next_frame): the frame in
    progress keeps its 10 ms, the next ones last the new 20 ms. Before, no such member."""
    prog = build_program([str(write(tmp_path, "next.cpp", NEXT_FRAME_CPP))])
    r = drive(dataclasses.replace(prog, isolate=isolate), track="floor", time_limit_s=2.0)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    assert [float(x.split()[1]) for x in out.splitlines() if x.startswith("period")] == [0.010, 0.020, 0.020], out


THREADS_C = """\
#include <pthread.h>
#include <stdint.h>
#include "spinner.h"
static void *worker(void *arg) {
    (void)arg;
#if CASE == 0
    spinner_get_time();                                    /* line 7 */
#elif CASE == 1
    spinner_get_time(); spinner_get_time();                /* line 9: and again, noted already */
#elif CASE == 2
    uint8_t row[8]; spinner_get_image(500, 1, row, 8);     /* line 11: a misused call */
#endif
    return NULL;
}
int main(void) {
    spinner_sleep(0.1);
    pthread_t t;
    pthread_create(&t, NULL, worker, NULL);
    pthread_join(t, NULL);
#ifndef RETURN_AT_ONCE
    spinner_get_time();                                    /* line 21 */
#endif
    return 0;
}
"""


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_spinner_call_from_another_thread_is_reported_at_the_threads_line(tmp_path, isolate):
    """Issue 50 (fault injection): a call from a thread of the program's own returned 0 in
    silence; the next call from main()'s thread reports it. The line named is the thread's call
    (the one to change), with the call's name; main()'s call that noticed it comes after (it was
    the line named: threads.c:21, not where the thread called)."""
    src = write(tmp_path, "threads.c", THREADS_C)
    program = build_program([src], defines=["CASE=0"])
    r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_error", r.message
    assert r.message.startswith(f"{src}:7: a Spinner call, spinner_get_time(), came from another thread than "
                                "the one running main() (it returned 0)"), r.message
    assert r.message.endswith(f"(in worker()); noticed by main()'s thread at its next call, {src}:21 (in main())"), \
        r.message
    text = r.error.traceback_text
    assert f"#0 worker at {src}:7\n" in text and f"#0 main at {src}:21\n" in text
    assert "libc" not in text  # (the thread's start cut, as the host's below main() is)


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_spinner_call_from_another_thread_is_reported_when_main_returns_without_another(tmp_path, isolate):
    """main() joins the thread and returns without a Spinner call of its own: the thread's call
    is reported as main() returns (the run ended controller_returned, the misuse unsaid)."""
    src = write(tmp_path, "threads.c", THREADS_C)
    program = build_program([src], defines=["CASE=0", "RETURN_AT_ONCE"])
    r = drive(dataclasses.replace(program, isolate=isolate), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_error", r.message
    assert r.message.startswith(f"{src}:7: a Spinner call, spinner_get_time(), came from another thread"), r.message


@pytest.mark.parametrize("case, line, said", [
    (1, 9, "(it returned 0)"),
    (2, 11, "ended that thread (spinner_get_image(line=500): expected -1 (whole image) or a row 0..127)"),
])
def test_a_threads_second_or_misused_spinner_call_does_not_take_over_the_simulator(tmp_path, case, line, said):
    """In the simulator's process a foreign thread's second Spinner call (the first one noted) or
    a misused one reported from that thread: it switched to the simulator's stack from there, and
    the simulator's Python went on in the program's thread (the process hung for good). Now only
    main()'s thread reports, naming the thread's first call; a misused call ends its thread."""
    src = write(tmp_path, "threads.c", THREADS_C)
    code = textwrap.dedent(f"""\
        from simrunner.run.native import build_program
        from simrunner.run.runner import drive
        r = drive(build_program([{str(src)!r}], defines=["CASE={case}"]), track="floor", time_limit_s=2.0)
        print(r.outcome, r.message, sep="\\n", flush=True)
        """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    outcome, _, message = done.stdout.strip().partition("\n")
    assert outcome == "controller_error", done.stdout + done.stderr
    assert message.startswith(f"{src}:{line}: a Spinner call, spinner_get_") and said in message, message
    assert message.endswith(f"noticed by main()'s thread at its next call, {src}:21 (in main())"), message


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_spinner_method_from_a_std_thread_names_the_programs_line(tmp_path, isolate):
    """C++: a std::thread calling a Spinner method (spinner.hpp's inline wrapper) is named at the
    program's line, with the method it called, not at spinner.hpp's line."""
    src = write(tmp_path, "threads.cpp", """\
        #include <thread>
        #include "spinner.hpp"
        static void worker(Spinner &s) { s.getTime(); }
        int main() {
            Spinner s;
            s.getImage(60);
            std::thread t([&s] { worker(s); });
            t.join();
            s.setSpeed(0.5);
            return 0;
        }
        """)
    r = drive(dataclasses.replace(build_program([src]), isolate=isolate), track="floor", time_limit_s=2.0)
    assert r.outcome == "controller_error", r.message
    assert r.message.startswith(f"{src}:3: a Spinner call, spinner_get_time(), came from another thread"), r.message
    assert r.message.endswith("(in worker(), calling Spinner::getTime()); noticed by main()'s thread at its next "
                              f"call, {src}:9 (in main())"), r.message


@pytest.mark.parametrize("mode", [[], ["-DSPINNER_INPROC"]])
def test_the_host_compiles_without_warnings(tmp_path, mode):
    """Both builds of host/spinner_host.c compile cleanly: an implicit declaration (pthread_self
    without <pthread.h> in the child's build) once compared truncated thread ids."""
    from simrunner.run.native.build import HOST_SOURCE, INCLUDE_DIR

    proc = subprocess.run(["cc", "-std=gnu11", "-Wall", "-Werror", "-fPIC", *mode, f"-I{INCLUDE_DIR}", "-c",
                           str(HOST_SOURCE), "-o", str(tmp_path / "host.o")], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("isolate", [False, True])
@pytest.mark.parametrize("limit_s, lines", [(5.0, 11), (0.05, 7)])
def test_exit_handlers_and_buffered_files_of_a_c_program_run_at_its_end(tmp_path, isolate, limit_s, lines):
    """Issue 50 (fault injection): in the simulator's process a controller's atexit handlers and
    its own buffered log file were lost (0 of 11 lines). Now they run and flush as exit() would,
    whether main returns (11 lines) or the run ends at the time limit (6 lines and the handler's)."""
    import dataclasses

    from simrunner.run.native import build_program

    log = tmp_path / "ctl_log.txt"
    src = tmp_path / "logs.c"
    src.write_text(textwrap.dedent(f"""\
        #include <stdio.h>
        #include <stdlib.h>
        #include "spinner.h"
        static FILE *log_file;
        static void bye(void) {{ fprintf(log_file, "atexit ran\\n"); fclose(log_file); }}
        int main(void) {{
            log_file = fopen("{log}", "w");
            atexit(bye);
            for (int i = 0; i < 10; i++) {{ fprintf(log_file, "line %d\\n", i); spinner_sleep(0.01); }}
            return 0;
        }}
        """))
    program = dataclasses.replace(build_program([str(src)]), isolate=isolate)
    drive(program, track="floor", time_limit_s=limit_s)
    text = log.read_text().splitlines()
    assert len(text) == lines and text[-1] == "atexit ran"


def test_a_cpp_programs_static_destructors_run_at_its_end(tmp_path):
    from simrunner.run.native import build_program

    log = tmp_path / "dtor.txt"
    src = tmp_path / "dtor.cpp"
    src.write_text(textwrap.dedent(f"""\
        #include <cstdio>
        #include "spinner.hpp"
        struct Logger {{
            FILE *f;
            Logger() {{ f = std::fopen("{log}", "w"); }}
            ~Logger() {{ std::fputs("destructor ran\\n", f); std::fclose(f); }}
        }};
        static Logger logger;
        int main() {{ std::fputs("main ran\\n", logger.f); spinner_sleep(0.05); return 0; }}
        """))
    program = build_program([str(src)])
    for _ in range(2):  # a second run of the same library: fresh globals, its destructor again
        log.unlink(missing_ok=True)
        assert drive(program, track="floor", time_limit_s=5.0).outcome == "controller_returned"
        assert log.read_text() == "main ran\ndestructor ran\n"


@pytest.mark.parametrize("isolate", [False, True])
@pytest.mark.parametrize("end, expected", [("return 0;", "main\natexit\ndestructor\n"),
                                           ("_exit(0);", "main\n")])
def test_a_c_programs_destructor_functions_run_at_its_end_as_exit_runs_them(tmp_path, isolate, end,
                                                                            expected):
    """Issue 50 (fault injection): in the simulator's process a C function marked
    ``__attribute__((destructor))`` never ran (the library's unloading came after the process's
    os._exit, or never). Now it runs at the program's end after the atexit handlers, as exit()
    runs it, and _exit skips it - also when the library is unloaded later."""
    import gc

    log = tmp_path / "log.txt"
    src = write(tmp_path, "dtor.c", f"""\
        #include <stdio.h>
        #include <stdlib.h>
        #include <unistd.h>
        #include "spinner.h"
        static FILE *f;
        static void bye(void) {{ fputs("atexit\\n", f); fflush(f); }}
        __attribute__((destructor)) static void dtor(void) {{ fputs("destructor\\n", f); fclose(f); }}
        int main(void) {{
            f = fopen("{log}", "w");
            atexit(bye);
            fputs("main\\n", f); fflush(f);
            spinner_sleep(0.02);
            {end}
        }}
        """)
    program = dataclasses.replace(build_program([src]), isolate=isolate)
    drive(program, track="floor", time_limit_s=1.0)
    assert log.read_text() == expected
    del program
    gc.collect()  # the library is unloaded: nothing more runs
    drive(build_program([write(tmp_path, "other.c", "int main(void) { return 0; }\n")]),
          track="floor", time_limit_s=0.1)
    assert log.read_text() == expected


FORKER = """\
    #include <stdio.h>
    #include <stdlib.h>
    #include <signal.h>
    #include <unistd.h>
    #include "spinner.h"
    int main(void) {
        uint8_t row[128];
        for (int i = 0; i < 5; i++) spinner_get_image(60, 1, row, sizeof row);
        pid_t waiter = fork();
        if (waiter == 0) { for (;;) pause(); }  /* a helper that never ends by itself */
        FILE *f = fopen("PIDFILE", "w");
        fprintf(f, "%d\\n", (int)waiter);
        fclose(f);
        pid_t pid = fork();  /* both processes go on driving: the child must not */
        for (int i = 0; i < 10; i++) {
            spinner_get_image(60, 1, row, sizeof row);
            spinner_set_speed_and_servo(0.5, 0.0);
        }
        printf("%s done\\n", pid == 0 ? "child" : "parent");
        return 0;
    }
    """


def _ended(pid: int) -> bool:
    """The process ``pid`` is gone (or a zombie waiting for init)."""
    try:
        return Path(f"/proc/{pid}/status").read_text().split("State:")[1].split()[0] == "Z"
    except (OSError, IndexError):
        return True


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="fork and /proc: Linux")
@pytest.mark.parametrize("isolate", [False, True])
def test_a_fork_in_a_c_controller_leaves_the_run_and_its_log_whole(tmp_path, isolate, capfd):
    """Issue 50 (fault injection): a controller's fork() ran the simulator twice (the child's
    copy went on with the run: frames written twice into the CSV, which then did not read back)
    and left a deadlocked orphan holding stdout. Now the child's Spinner call ends it with a
    message, the log holds each frame once, and a helper still running ends with the run."""
    import time

    pidfile = tmp_path / "helper.pid"
    src = write(tmp_path, "forker.c", FORKER.replace("PIDFILE", str(pidfile)))
    program = dataclasses.replace(build_program([src]), isolate=isolate)
    result = drive(program, track="floor", time_limit_s=2.0, csv=tmp_path / "run.csv")
    assert result.outcome == "controller_returned"
    out, err = capfd.readouterr()
    assert out.count("parent done") == 1 and "child done" not in out
    assert "which the controller fork()ed from process" in err and "exit status 70" in err
    frames = read_log(tmp_path / "run.csv").frame
    assert list(frames) == list(range(len(frames))) and len(frames) == 16
    helper = int(pidfile.read_text())
    for _ in range(100):  # in-process it is reaped at the run's end; isolated, init reaps it
        if _ended(helper):
            break
        time.sleep(0.05)
    assert _ended(helper)


def test_a_program_run_elsewhere_leaves_no_exit_handlers_for_the_next(tmp_path):
    """A C++ global with a destructor whose constructor calls Spinner: loaded in the simulator's
    process, its destructor was registered (at the load) and the library unloaded when the program
    went to a child process; the next in-process program's end called that destructor in unloaded
    code and the simulator's process died (SIGSEGV). Both runs in a fresh process: it must end 0."""
    src = tmp_path / "ctor.cpp"
    src.write_text(textwrap.dedent("""\
        #include <cstdio>
        #include "spinner.h"
        struct Gains {
            double kp;
            Gains() : kp(spinner_param("kp", 0.5)) {}
            ~Gains() { std::printf("gains gone\\n"); }
        } gains;
        int main() { spinner_sleep(0.1); return 0; }
        """))
    plain = tmp_path / "plain.c"
    plain.write_text('#include "spinner.h"\nint main(void) { spinner_sleep(0.1); return 0; }\n')
    code = textwrap.dedent(f"""\
        from simrunner.run.native import build_program
        from simrunner.run.runner import drive
        for path in ({str(src)!r}, {str(plain)!r}):
            r = drive(build_program([path]), time_limit_s=1.0)
            print(path, r.outcome)
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, (out.returncode, out.stdout, out.stderr[-2000:])
    assert out.stdout.count("controller_returned") == 2, out.stdout


def test_a_program_run_elsewhere_leaves_no_library_types_destructor_for_the_next(tmp_path):
    """The same with a global of a library's type (a std::string): its destructor is libstdc++'s
    (registered with the object, in the unloaded library, and its __dso_handle), so the handlers
    dropped by their function's module kept it: the next program's end freed the unloaded string
    ('munmap_chunk(): invalid pointer', that run's SIGABRT; or SIGSEGV of the process)."""
    src = write(tmp_path, "label.cpp", """\
        #include <cstdio>
        #include <string>
        #include "spinner.h"
        std::string label = "a label long enough to live on the heap, not in the string itself";
        struct Gains { double kp; Gains() : kp(spinner_param("kp", 0.5)) {} } gains;
        int main() { std::printf("%s\\n", label.c_str()); spinner_sleep(0.1); return 0; }
        """)
    plain = write(tmp_path, "plain.c", '#include "spinner.h"\nint main(void) { spinner_sleep(0.1); return 0; }\n')
    code = textwrap.dedent(f"""\
        from simrunner.run.native import build_program
        from simrunner.run.runner import drive
        for path in ({str(src)!r}, {str(plain)!r}):
            r = drive(build_program([path]), time_limit_s=1.0)
            print(path, r.outcome, r.message)
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, (out.returncode, out.stdout, out.stderr[-2000:])
    assert out.stdout.count("controller_returned") == 2, (out.stdout, out.stderr[-2000:])


def test_a_global_objects_constructor_that_calls_spinner_runs_as_isolated(tmp_path, track, capfd):
    """A C++ global whose constructor reads a parameter: in the simulator's process the library's
    constructors run as it is loaded, before the run, where nothing can be asked (the run crashed,
    SIGSEGV before its first frame): the program runs in a child process instead, its constructor
    reading the run's --param as with --isolate."""
    src = tmp_path / "ctor.cpp"
    src.write_text(textwrap.dedent("""\
        #include <cstdio>
        #include "spinner.h"
        struct Gains { double kp; Gains() : kp(spinner_param("kp", 0.5)) {} } gains;
        int main() {
            std::printf("kp %g\\n", gains.kp);
            spinner_sleep(0.1);
            return 0;
        }
        """))
    prog = build_program([str(src)])
    for isolate in (False, True):
        r = drive(dataclasses.replace(prog, isolate=isolate), track=track, params={"kp": 2.5}, time_limit_s=1.0)
        assert r.outcome == "controller_returned", r.message
        assert "kp 2.5" in capfd.readouterr().out


def test_a_c_constructors_early_calls_are_answered_as_after_a_run(tmp_path, track, capfd):
    """A C constructor (``__attribute__((constructor))``) reading a parameter: at the library's load
    in the simulator's process its spinner_param returned what its stack held (0 here: a buffer
    sized by it, a loop bound by it), not its default; now the default (the program then runs in a
    child process, where the run's value is read)."""
    src = write(tmp_path, "ctor.c", """\
        #include <stdio.h>
        #include "spinner.h"
        __attribute__((constructor)) static void early(void) { printf("ctor n=%g\\n", spinner_param("n", 3)); }
        int main(void) { spinner_sleep(0.1); return 0; }
        """)
    r = drive(build_program([src]), track=track, time_limit_s=1.0)
    assert r.outcome == "controller_returned", r.message
    out = capfd.readouterr().out
    assert out.count("ctor n=3") == 2 and "ctor n=" not in out.replace("ctor n=3", ""), out


@pytest.mark.parametrize("after_a_run", [False, True])
def test_an_exit_in_a_constructor_at_the_load_ends_the_simulator_saying_why(tmp_path, after_a_run):
    """exit(3) in a C constructor as the library is loaded in the simulator's process (before any
    run; nothing can be left or continued there): it ended the simulator's thread (the process's
    status 0, no output at all) or, after an earlier run, switched to that run's stack (SIGSEGV).
    Now the simulator ends (status 70) naming the call and --isolate (simrunner drive's supervisor
    tells the run's outcome: test_an_end_in_a_constructor_at_the_load_is_the_runs_outcome_as_isolated);
    isolated it is the run's."""
    src = write(tmp_path, "ctor_exit.c", """\
        #include <stdlib.h>
        #include "spinner.h"
        __attribute__((constructor)) static void early(void) { exit(3); }
        int main(void) { spinner_sleep(0.1); return 0; }
        """)
    plain = write(tmp_path, "plain.c", '#include "spinner.h"\nint main(void) { spinner_sleep(0.1); return 0; }\n')
    paths = [str(plain), str(src)] if after_a_run else [str(src)]
    code = textwrap.dedent(f"""\
        from simrunner.run.native import build_program
        from simrunner.run.runner import drive
        for path in {paths!r}:
            print(path, drive(build_program([path]), time_limit_s=1.0).outcome, flush=True)
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 70, (out.returncode, out.stdout, out.stderr[-2000:])
    line, = [t for t in out.stderr.splitlines() if t.startswith("simrunner:")]
    assert re.match(r"simrunner: the controller called exit\(3\) at \S+\.so\+0x[0-9a-f]+, in a constructor as the "
                    r"controller's library was loaded into the simulator's process, before the run", line), line
    assert "--isolate" in line
    r = drive(isolated(src), time_limit_s=1.0)
    assert r.outcome == "controller_error" and "exit(3) at" in r.message and "ctor_exit.c:3" in r.message, r.message


CTOR_FAULTS = {
    "c.c": ("""\
        #include "spinner.h"
        static int *p;
        __attribute__((constructor)) static void boom(void) {
            *p = 3;                                      /* line 4 */
        }
        int main(void) { while (1) { spinner_set_speed(0.5f); spinner_sleep(0.01f); } }
        """, "c.c:4: SIGSEGV: segmentation fault (in boom())"),
    "g.cpp": ("""\
        #include "spinner.h"
        struct Car {
            int *wheels = nullptr;
            Car() { wheels[2] = 1; }                     /* line 4 */
        };
        Car car;
        int main() { while (true) { spinner_set_speed(0.5f); spinner_sleep(0.01f); } }
        """, "g.cpp:4: SIGSEGV: segmentation fault (in Car::Car())"),
}


def _cli_drive(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    """``simrunner drive ARGS`` as a command (supervised: its own process, real stdout/stderr)."""
    return subprocess.run([sys.executable, "-c", "from simrunner.cli import main; main()", "drive", *args],
                          cwd=cwd, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(REPO)})


@pytest.mark.parametrize("name", sorted(CTOR_FAULTS))
def test_a_fault_in_a_constructor_at_the_load_names_its_line_as_isolated(tmp_path, name):
    """A fault in a C constructor (a C++ global object's) runs as the library is loaded into the
    simulator's process, before the run and its handlers: the process died and drive said only
    'killed by SIGSEGV before the first frame'. Now the host reports it to the supervisor, which
    names its file:line and function as --isolate does, and says --isolate."""
    body, said = CTOR_FAULTS[name]
    write(tmp_path, name, body)
    done = _cli_drive(tmp_path, name, "--summary", "s.json")
    summary = json.loads((tmp_path / "s.json").read_text())
    assert done.returncode == 1, (done.stdout, done.stderr[-2000:])
    assert summary["outcome"] == "controller_error"
    assert summary["message"].startswith(f"{said}, in a constructor as the program loaded, before the first "
                                         "frame"), summary["message"]
    assert "--isolate runs the program in a process of its own" in summary["message"]
    assert f"outcome: controller_error ({summary['message']})" in done.stdout
    assert re.search(rf"#0 \S+ at {re.escape(name)}:4", done.stderr), done.stderr[-2000:]  # the C backtrace
    isolated_run = _cli_drive(tmp_path, name, "--isolate", "--summary", "i.json")
    assert json.loads((tmp_path / "i.json").read_text())["message"] == said, isolated_run.stdout


def test_a_fault_in_a_constructor_at_the_load_unsupervised_says_one_line(tmp_path):
    """The Python API in a process of its own (no supervisor to report to): the process still
    dies by the signal (it died silently), saying where on stderr and pointing to --isolate."""
    src = write(tmp_path, "c.c", CTOR_FAULTS["c.c"][0])
    code = textwrap.dedent(f"""\
        from simrunner.run.native import build_program
        from simrunner.run.runner import drive
        program = build_program([{str(src)!r}])
        print("built", flush=True)
        drive(program, time_limit_s=1.0)
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == -11 and out.stdout == "built\n", (out.returncode, out.stdout, out.stderr[-2000:])
    line, = [t for t in out.stderr.splitlines() if t.startswith("simrunner:")]
    assert re.match(r"simrunner: SIGSEGV at \S+\.so\+0x[0-9a-f]+, in a constructor as the controller's library "
                    r"was loaded into the simulator's process, before the run", line), line
    assert "--isolate" in line


THREAD_FAULT_SAID = ("t.c:5: SIGSEGV: segmentation fault (in worker()), in a thread of the program's own (not "
                     "main()'s)")


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_fault_in_a_thread_of_the_programs_own_names_the_threads_line(tmp_path, isolate):
    """A thread the program started (not main()'s) dereferences NULL while main() drives. In the
    simulator's process the fault went to the simulator's handler and killed the process: drive said
    'the run's process was killed by SIGSEGV at t = ... (a crash the simulator could not catch ...)',
    no line. Isolated the line was named, but not that it was another thread's. Now both name the
    thread's file:line and function and say it was a thread of the program's; in process the host
    reports it to the supervisor before the process dies by the signal, which writes the outputs
    from the run log (the rows up to the fault)."""
    write(tmp_path, "t.c", C_THREAD_FAULT)
    done = _cli_drive(tmp_path, "t.c", "--summary", "s.json", "--csv", "c.csv", *(["--isolate"] if isolate else []))
    assert done.returncode == 1, (done.stdout, done.stderr[-2000:])
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["outcome"] == "controller_error"
    if isolate:
        assert summary["message"] == THREAD_FAULT_SAID
    else:
        assert summary["message"] == (
            f"{THREAD_FAULT_SAID}: it killed the run's process (the program runs in the simulator's process, where "
            "a fault of its threads cannot be caught; --isolate runs the program in a process of its own); the "
            "outputs were written from the run log")
    assert f"outcome: controller_error ({summary['message']})" in done.stdout
    assert summary["frames"] >= 20 and len(read_log(tmp_path / "c.csv")) == summary["frames"]
    assert "C controller t: segmentation fault (invalid memory access), in a thread of the program's own (not " \
           "main()'s)\nC backtrace (innermost first):\n  #0 worker at t.c:5\n" in done.stderr, done.stderr[-2000:]
    assert "libc" not in done.stderr  # (the thread's start cut, as the host's below main() is)



@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
@pytest.mark.parametrize("name, body, function", [("t.c", C_THREAD_OVERFLOW, "recurse()"),
                                                  ("t.cpp", CXX_THREAD_OVERFLOW, "recurse(int)")])
def test_a_stack_overflow_in_a_thread_of_the_programs_own_names_the_threads_line(tmp_path, isolate, name, body,
                                                                                function):
    """A thread the program started (pthread_create, std::thread) recurses without end. Its thread
    had no alternate signal stack, so the handler could not run on the overflowed stack: drive said
    only 'the run's process was killed by SIGSEGV at t = ...' (in process) or 't: the controller was
    killed by SIGSEGV' (isolated), no line. Now each thread the program starts gets one (the host's
    thread start): the overflow is named at the recursing function's line as a fault of the thread's,
    'stack overflow' as main()'s is, with the rows up to it kept."""
    write(tmp_path, name, body)
    done = _cli_drive(tmp_path, name, "--summary", "s.json", "--csv", "c.csv", *(["--isolate"] if isolate else []))
    assert done.returncode == 1, (done.stdout, done.stderr[-2000:])
    summary = json.loads((tmp_path / "s.json").read_text())
    said = f"{name}:5: SIGSEGV: stack overflow (in {function}), in a thread of the program's own (not main()'s)"
    assert summary["outcome"] == "controller_error"
    assert summary["message"] == (said if isolate else f"{said}: it killed the run's process (the program runs in "
                                  "the simulator's process, where a fault of its threads cannot be caught; --isolate "
                                  "runs the program in a process of its own); the outputs were written from the run "
                                  "log")
    assert summary["frames"] >= 20 and len(read_log(tmp_path / "c.csv")) == summary["frames"]
    assert f"stack overflow (the thread's stack), in a thread of the program's own (not main()'s)\nC backtrace " \
           f"(innermost first):\n  #0 {function.replace('()', '')} at {name}:5\n" in done.stderr, done.stderr[-2000:]


def test_a_stack_overflow_in_a_prebuilt_librarys_thread_names_its_line(tmp_path):
    """The same in a prebuilt library (run isolated, not linked by simrunner): its pthread_create is
    the host program's, which gives the thread its alternate signal stack too."""
    src = write(tmp_path, "t.c", C_THREAD_OVERFLOW)
    lib = tmp_path / "libt.so"
    subprocess.run(["cc", "-shared", "-fPIC", "-g", "-O0", cflags(), str(src), "-o", str(lib)], check=True,
                   capture_output=True)
    r = drive(build_program([str(lib)]), track="floor", time_limit_s=5.0)
    assert r.outcome == "controller_error"  # (-O0: in the function's prologue, its line 4, or its body's)
    assert re.fullmatch(rf"{re.escape(str(src))}:[45]: SIGSEGV: stack overflow \(in recurse\(\)\), in a thread of "
                        r"the program's own \(not main\(\)'s\)", r.message), r.message


def test_the_programs_threads_still_run_join_and_return_their_values(tmp_path, track, capfd):
    """The host's thread start (the alternate signal stack) changes nothing else: a pthread's return
    value reaches pthread_join, a std::thread's lambda runs and joins, pthread_exit's value too."""
    c = write(tmp_path, "j.c", """\
        #include <pthread.h>
        #include <stdio.h>
        #include "spinner.h"
        static void *twice(void *arg) { return (void *)(2 * (long)arg); }
        static void *leaves(void *arg) { pthread_exit((void *)(3 * (long)arg)); }
        int main(void) {
            pthread_t a, b;
            void *ra, *rb;
            pthread_create(&a, NULL, twice, (void *)21L);
            pthread_create(&b, NULL, leaves, (void *)5L);
            pthread_join(a, &ra);
            pthread_join(b, &rb);
            printf("joined %ld %ld\\n", (long)ra, (long)rb);
            spinner_sleep(0.05);
            return 0;
        }
        """)
    cxx = write(tmp_path, "j.cpp", """\
        #include <cstdio>
        #include <thread>
        #include "spinner.h"
        int main() {
            int x = 0;
            std::thread t([&x] { x = 42; });
            t.join();
            std::printf("joined %d\\n", x);
            spinner_sleep(0.05);
            return 0;
        }
        """)
    for src, said in ((c, "joined 42 15\n"), (cxx, "joined 42\n")):
        for isolate in (False, True):
            r = drive(dataclasses.replace(build_program([src]), isolate=isolate), track=track, time_limit_s=1.0)
            assert r.outcome == "controller_returned", r.message
            assert capfd.readouterr().out.endswith(said)


LEFT_RUNNING_C = """\
#include <poll.h>
#include <pthread.h>
#include "spinner.h"
static int *volatile nowhere;
static void *worker(void *arg) {
    poll(NULL, 0, 1500);                                 /* (after the run) */
    if (arg) *nowhere = 1;                               /* line 7 */
    return arg;
}
int main(void) {
    pthread_t t;
    pthread_create(&t, NULL, worker, (void *)(long)FAULTS);
    for (int k = 0; k < 5; k++) spinner_sleep(0.01);
    return 0;
}
"""


@pytest.mark.parametrize("faults", [0, 1], ids=["returns", "faults"])
def test_a_thread_left_running_after_an_in_process_run_keeps_its_library_loaded(tmp_path, faults):
    """A program's main() returns while a thread it started still runs (it waits 1.5 s). Its library
    was unloaded after the run: the thread went on in unmapped code and killed the process a second
    later, in the next program's run (a batch worker's, a test process's), unreported (-11, nothing
    said), even a thread that would only have returned. Now the library stays loaded while its
    threads run (the run warns once): a thread that returns harms nothing, and one that faults is
    named as the program's thread left running (one line on stderr, no supervisor here)."""
    src = write(tmp_path, "left.c", LEFT_RUNNING_C)
    plain = write(tmp_path, "plain.c", '#include "spinner.h"\nint main(void) { spinner_sleep(0.1); return 0; }\n')
    code = textwrap.dedent(f"""\
        import time
        from simrunner.run.native import build_program
        from simrunner.run.runner import drive
        r = drive(build_program([{str(src)!r}], defines=["FAULTS={faults}"]), track="floor", time_limit_s=1.0)
        print("first", r.outcome, r.warnings, flush=True)
        time.sleep(3.0)  # (the thread's wait is over)
        r = drive(build_program([{str(plain)!r}]), track="floor", time_limit_s=1.0)
        print("second", r.outcome, flush=True)
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    first = out.stdout.splitlines()[0] if out.stdout else ""
    assert first.startswith("first controller_returned ['the C/C++ program left 1 thread running (not waited "
                            "for): its library stays loaded in this process while they run"), (out.returncode,
                                                                                                 out.stdout,
                                                                                                 out.stderr[-2000:])
    if not faults:
        assert out.returncode == 0 and "second controller_returned" in out.stdout, (out.returncode, out.stderr[-2000:])
        return
    assert out.returncode == -11, (out.returncode, out.stdout, out.stderr[-2000:])
    line, = [t for t in out.stderr.splitlines() if t.startswith("simrunner:")]
    assert re.match(r"simrunner: SIGSEGV at \S+\.so\+0x[0-9a-f]+, in a thread a C/C\+\+ program started and left "
                    r"running after its run in the simulator's process \(its library was kept loaded for it\): the "
                    r"process ends", line), line


def test_a_fault_of_a_thread_an_earlier_run_left_running_is_named_so():
    """Its report to a later run's supervisor (a batch worker's next run): named at its line, as an
    earlier run's thread that killed this run's process, not as this run's program's."""
    from simrunner.run.postmortem import thread_fault

    report = ("thread-fault /nowhere/left.so\nhost /nowhere/host.so\nstray\nsignal 11\nmessage \n"
              "thread program\n")
    error = thread_fault(report, "plain.c")
    assert str(error).startswith("SIGSEGV: segmentation fault, in a thread of the program's own (not main()'s): a "
                                 "thread an earlier run's program in this process left running (not waited for), "
                                 "which killed this run's process"), str(error)

RACING_THREADS_C = """\
#include <pthread.h>
#include <string.h>
#include "spinner.h"
static int *volatile nowhere;
static volatile int go;
static void *worker(void *arg) {
    while (!go) {}
    for (volatile int k = 0; k < 200000; k++) {}
    *nowhere = 1;                                        /* line 9 */
    return arg;
}
static char text[6000];
int main(void) {
    static uint8_t row[4096];
    const char *lines[1] = {text};
    pthread_t t[3];
    memset(text, 'x', sizeof text - 1);
    for (int k = 0; k < 3; k++) pthread_create(&t[k], NULL, worker, NULL);
    for (int frame = 0;; frame++) {
        spinner_get_image(spinner_line_row(), 0, row, sizeof row);
        spinner_set_speed(0.5);
        if (frame == 5) go = 1;
        for (int k = 0; k < 200; k++) spinner_add_text(lines, 1);  /* 1.2 MB a frame: main() writes */
    }
}
"""


def test_isolated_a_fault_in_the_programs_threads_is_one_report_whatever_main_sends(tmp_path):
    """Isolated, three threads of the program's fault at once while main()'s thread sends 1.2 MB of
    text a frame: each faulting thread wrote its report into the pipe amid main()'s messages and the
    others' (measured: 'race: the controller exited with status 70' in 10 runs of 10, the fault
    unsaid). Now the first thread's report goes out alone, between two of main()'s messages: every
    run names the line."""
    src = write(tmp_path, "race.c", RACING_THREADS_C)
    program = isolated(src)
    messages = [drive(program, track="floor", time_limit_s=5.0).message for _ in range(10)]
    assert messages == [f"{src}:9: SIGSEGV: segmentation fault (in worker()), in a thread of the program's own "
                        "(not main()'s)"] * 10


def test_a_fault_in_a_programs_thread_unsupervised_says_one_line(tmp_path):
    """The Python API in a process of its own (no supervisor to report to): the process dies by the
    signal (as before, when it said nothing), saying where on stderr and pointing to --isolate."""
    src = write(tmp_path, "t.c", C_THREAD_FAULT)
    code = textwrap.dedent(f"""\
        from simrunner.run.native import build_program
        from simrunner.run.runner import drive
        program = build_program([{str(src)!r}])
        print("built", flush=True)
        drive(program, time_limit_s=5.0)
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == -11 and out.stdout == "built\n", (out.returncode, out.stdout, out.stderr[-2000:])
    line, = [t for t in out.stderr.splitlines() if t.startswith("simrunner:")]
    assert re.match(r"simrunner: SIGSEGV at \S+\.so\+0x[0-9a-f]+, in a thread of the program's own \(not main\(\)'s\), "
                    r"which runs in the simulator's process: the process ends", line), line
    assert "--isolate" in line


def test_a_fault_in_a_thread_not_the_programs_still_goes_to_the_handler_before(tmp_path):
    """During an in-process run a thread of the simulator's own (a Python thread: ctypes reading
    address 0) faults: it is not the program's (no frame in its library), so the handler installed
    before the run's gets it as ever (faulthandler's, here), and no thread-fault report is made."""
    src = write(tmp_path, "slow.c", """\
        #include "spinner.h"
        int main(void) { for (;;) { spinner_set_speed(0.5); spinner_sleep(0.01); } }
        """)
    code = textwrap.dedent(f"""\
        import ctypes, threading, time
        from simrunner.run.native import build_program
        from simrunner.run.runner import drive
        program = build_program([{str(src)!r}])
        def crash():
            time.sleep(0.5)  # (the run is on)
            ctypes.string_at(0)
        threading.Thread(target=crash, daemon=True).start()
        drive(program, track="floor", time_limit_s=600.0)
        """)
    out = subprocess.run([sys.executable, "-X", "faulthandler", "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == -11, (out.returncode, out.stdout, out.stderr[-2000:])
    assert "Fatal Python error: Segmentation fault" in out.stderr and "in crash" in out.stderr, out.stderr[-2000:]
    assert "simrunner:" not in out.stderr


@pytest.mark.parametrize("name", sorted(C_CTOR_ENDS))
def test_an_end_in_a_constructor_at_the_load_is_the_runs_outcome_as_isolated(tmp_path, name):
    """exit(3), exit(0), spinner_fail, a misused Spinner call in a C constructor, quick_exit in a C++
    global object's, as the library is loaded into the simulator's process before the run: nothing
    returns out of the loader, the process ends (status 70) - and simrunner drive ended with it, one
    line on stderr, no summary, plot or CSV, no outcome line. Now the host reports the call to the
    supervisor, which tells the run's outcome as --isolate does (the call and its file:line), says
    where it was, writes the outputs (the CSV's header: no frame was run) and exits as for that
    outcome (exit(0): controller_returned, 0)."""
    body, outcome, said = C_CTOR_ENDS[name]
    write(tmp_path, name, body)
    done = _cli_drive(tmp_path, name, "--summary", "s.json", "--csv", "c.csv", "--plot", "p.png")
    assert done.returncode == (0 if outcome == "controller_returned" else 1), (done.stdout, done.stderr[-2000:])
    summary = json.loads((tmp_path / "s.json").read_text())
    message = f"{said}, in a constructor as the program loaded, before the first frame"
    assert (summary["outcome"], summary["message"]) == (outcome, message)
    assert summary["frames"] == 0 and summary["sim_time_s"] == 0.0
    assert f"outcome: {outcome} ({message})" in done.stdout
    assert "wrote: c.csv, p.png, s.json" in done.stdout
    assert len(read_log(tmp_path / "c.csv")) == 0 and (tmp_path / "p.png").stat().st_size > 0
    if name in ("fail.c", "misuse.c"):  # the C backtrace, as isolated
        assert re.search(rf"#0 \S+ at {re.escape(name)}:\d", done.stderr), done.stderr[-2000:]
    isolated_run = _cli_drive(tmp_path, name, "--isolate", "--summary", "i.json")
    assert isolated_run.returncode == done.returncode
    # isolated, the run has begun (its frame at t = 0): an exit is said to be a constructor's
    isolated = f"{said}, in a constructor as the program loaded" if said.startswith("the controller called") else said
    assert json.loads((tmp_path / "i.json").read_text())["message"] == isolated, isolated_run.stdout


def test_a_run_ended_in_a_constructor_says_it_wrote_no_video_and_no_earlier_runs_log(tmp_path):
    """exit(3) in a C constructor as the library loads in the simulator's process, with --video,
    --csv and --summary, where an earlier run wrote its CSV: the run said nothing of the video asked
    for (none was written: no frame), and the earlier run's CSV, untouched, was read as this run's
    log (its frames, its simulated time in the summary; 'wrote: c.csv'). Now it says there is no
    video and why, and the CSV is this run's: its header only."""
    write(tmp_path, "plain.c", '#include "spinner.h"\nint main(void) { spinner_sleep(0.1); return 0; }\n')
    write(tmp_path, "exit3.c", C_CTOR_ENDS["exit3.c"][0])
    assert _cli_drive(tmp_path, "plain.c", "--csv", "c.csv").returncode == 0
    assert len(read_log(tmp_path / "c.csv")) > 0
    done = _cli_drive(tmp_path, "exit3.c", "--video", "v.mp4", "--csv", "c.csv", "--summary", "s.json")
    assert done.returncode == 1, (done.stdout, done.stderr[-2000:])
    summary = json.loads((tmp_path / "s.json").read_text())
    assert "warning: no video: the run ended before its first camera frame\n" in done.stderr, done.stderr[-2000:]
    assert summary["warnings"] == ["no video: the run ended before its first camera frame"]
    assert "wrote: c.csv, s.json\n" in done.stdout, done.stdout
    assert not (tmp_path / "v.mp4").exists() and not (tmp_path / "v.partial.mp4").exists()
    assert summary["frames"] == 0 and summary["sim_time_s"] == 0.0
    assert len(read_log(tmp_path / "c.csv")) == 0

@pytest.mark.parametrize("name, said", [
    ("fail.c", 'the controller called spinner_fail("no calibration table") at '),
    ("misuse.c", "a misused Spinner call (spinner_every(period_s=-1): expected at least 1e-05 s (a 100 kHz timer)) "
                 "at ")])
def test_an_end_in_a_constructor_at_the_load_unsupervised_says_it_in_one_line(tmp_path, name, said):
    """The Python API in a process of its own (no supervisor): one line on stderr, status 70. A misused
    call's line was cut at 64 characters ('... (spinner_every(period_s=0.01, handler=NU in a global
    object's constructor') and neither it nor spinner_fail's said the message or where."""
    src = write(tmp_path, name, C_CTOR_ENDS[name][0])
    code = textwrap.dedent(f"""\
        from simrunner.run.native import build_program
        from simrunner.run.runner import drive
        drive(build_program([{str(src)!r}]), time_limit_s=1.0)
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 70, (out.returncode, out.stdout, out.stderr[-2000:])
    line, = [t for t in out.stderr.splitlines() if t.startswith("simrunner:")]
    assert line.startswith(f"simrunner: {said}"), line
    assert re.search(r"\.so\+0x[0-9a-f]+( \((early|check)\))?, in a constructor as the controller's library was "
                     r"loaded into the simulator's process, before the run", line), line
    assert line.endswith("--isolate runs the program in a process of its own, where its constructors run with "
                         "the run)"), line


@pytest.mark.parametrize("name, said", [
    ("boom.c", "boom.c:5: SIGSEGV: segmentation fault (in boom())"),
    ("exit3.c", "the controller called exit(3) at exit3.c:4, in a constructor as the program loaded")])
def test_simrunner_check_reports_a_constructor_that_ends_the_program_at_its_load(tmp_path, name, said):
    """simrunner check has no supervisor: a fault or an exit in a C constructor, run as the library
    was loaded into its process, ended it (killed by SIGSEGV; status 70, one line) without a
    report. It runs C/C++ programs isolated: the problem is named as --isolate names it."""
    write(tmp_path, name, C_CTOR_FAULT if name == "boom.c" else C_CTOR_ENDS[name][0])
    done = subprocess.run([sys.executable, "-c", "from simrunner.cli import main; main()", "check", name],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 1, (done.returncode, done.stdout, done.stderr[-2000:])
    assert done.stdout.startswith(f"{name}: PROBLEMS") and f": {said}\n" in done.stdout, done.stdout


def test_a_library_loaded_while_another_thread_runs_a_program_in_process(tmp_path, track, capfd):
    """A program (its constructor reading a parameter) loaded in one thread while another thread's
    run is on in this process: its constructor's call was taken as a call of that run's program from
    a foreign thread (that run ended 'a Spinner call came from another thread') and not as an early
    call (the program then ran in process, its constructor's kp 0, not the run's --param)."""
    import threading

    started, stop = tmp_path / "started", tmp_path / "stop"
    runner = write(tmp_path, "runner.c", f"""\
        #include <stdio.h>
        #include <unistd.h>
        #include "spinner.h"
        int main(void) {{
            fclose(fopen("{started}", "w"));
            while (access("{stop}", F_OK) != 0) spinner_sleep(0.01);
            return 0;
        }}
        """)
    ctor = write(tmp_path, "ctor.cpp", """\
        #include <cstdio>
        #include "spinner.h"
        struct Gains { double kp; Gains() : kp(spinner_param("kp", 0.5)) {} } gains;
        int main() { std::printf("kp %g\\n", gains.kp); spinner_sleep(0.1); return 0; }
        """)
    first, second = build_program([runner]), build_program([ctor])
    result = {}
    t = threading.Thread(target=lambda: result.setdefault("r", drive(first, track=track, time_limit_s=600.0)))
    t.start()
    try:
        for _ in range(600):
            if started.exists() or not t.is_alive():
                break
            import time
            time.sleep(0.05)
        assert started.exists()
        controller = load_native(second)  # its library opened here, the other run on
        assert t.is_alive()
    finally:
        stop.touch()
        t.join()
    assert result["r"].outcome == "controller_returned", result["r"].message
    assert not controller.inproc  # early: it runs in a child process
    r = drive(controller, track=track, params={"kp": 2.5}, time_limit_s=1.0)
    assert r.outcome == "controller_returned", r.message
    assert "kp 2.5" in capfd.readouterr().out


def test_a_programs_exit_handlers_run_at_its_own_end_not_an_earlier_programs(tmp_path):
    """Two C/C++ programs opened (loaded in process) before either runs: the second's static
    destructors, registered at its load, ran at the first's end (its 'G gone' printed there, its
    std::string freed before its own run read it: garbage, or a crash) and were gone at its own."""
    src = write(tmp_path, "label.cpp", """\
        #include <cstdio>
        #include <string>
        #include "spinner.h"
        std::string label = "a label long enough to live on the heap, not in the string itself";
        struct G { ~G() { std::printf("G gone\\n"); } } g;
        int main() { std::printf("label: %s\\n", label.c_str()); spinner_sleep(0.1); return 0; }
        """)
    plain = write(tmp_path, "plain.c", """\
        #include <stdio.h>
        #include "spinner.h"
        int main(void) { spinner_sleep(0.1); printf("plain done\\n"); return 0; }
        """)
    code = textwrap.dedent(f"""\
        from simrunner.run.native import build_program, load_native
        from simrunner.run.runner import drive
        first, second = load_native(build_program([{str(plain)!r}])), load_native(build_program([{str(src)!r}]))
        print("first", drive(first, time_limit_s=1.0).outcome, flush=True)
        print("second", drive(second, time_limit_s=1.0).outcome, flush=True)
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, (out.returncode, out.stdout, out.stderr[-2000:])
    assert out.stdout.split() == ["plain", "done", "first", "controller_returned", "label:", "a", "label", "long",
                                  "enough", "to", "live", "on", "the", "heap,", "not", "in", "the", "string",
                                  "itself", "G", "gone", "second", "controller_returned"], out.stdout
