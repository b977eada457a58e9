"""The microcontroller's time (issue 50 item 3, simrunner.run.mcu): --mcu-time makes the
controller's own processing cost simulated time, measured (times --mcu-scale) or fixed."""
from __future__ import annotations

import dataclasses
import textwrap
import time

import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.run.runner import drive
from simrunner.run.settings import RunSettings, SettingsError


def test_a_fixed_cost_per_call_passes_in_simulated_time_deterministically():
    def gaps(**kw):
        times = []
        drive(lambda s: times.extend(s.get_time() for _ in range(5)), track="floor", time_limit_s=5, **kw)
        return [round(b - a, 9) for a, b in zip(times, times[1:])]

    assert gaps() == [0.002] * 4  # get_time lets one physics step pass
    assert gaps(mcu_time=0.05) == [0.052] * 4  # each call first lets the 50 ms pass
    assert gaps(mcu_time=0.001) == [0.004, 0.002, 0.004, 0.002]  # half steps carried to the next call


def test_the_thesiss_camel_case_names_are_charged_as_their_methods():
    """``getTime``, ``getImage``, ... (the thesis's C++ names) are the same calls: each lets the
    controller's time pass first (they let none: the charge wrapped the snake_case names only)."""
    def gaps(name):
        times = []
        drive(lambda s: times.extend(getattr(s, name)() for _ in range(3)), track="floor", time_limit_s=5,
              mcu_time=0.05)
        return [round(b - a, 9) for a, b in zip(times, times[1:])]

    assert gaps("getTime") == gaps("get_time") == [0.052] * 2


def test_measured_processing_time_makes_a_slow_controller_miss_frames():
    def main(s):
        while True:
            s.get_image(s.line_row)
            t0 = time.thread_time()
            while time.thread_time() - t0 < 0.004:  # 4 ms of work per frame
                pass
            s.set_speed_and_servo(0.5, 0.0)

    def frames(**kw):
        seen = []

        def counting(s):
            orig = s.get_image

            def get_image(*a, **k):
                seen.append(s.get_time())
                return orig(*a, **k)

            s.get_image = get_image
            main(s)

        drive(counting, track="floor", time_limit_s=2.0, **kw)
        return len(seen)

    plain = frames()
    slow = frames(mcu_time="measured", mcu_scale=10.0)  # 40 ms per frame at a 20 ms frame period
    assert plain >= 95 and slow < 0.7 * plain


def test_a_c_program_reports_its_own_cpu_time(tmp_path):
    src = tmp_path / "busy.c"
    src.write_text(textwrap.dedent("""\
        #include <time.h>
        #include "spinner.h"
        static double cpu(void) {
            struct timespec ts;
            clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
            return ts.tv_sec + 1e-9 * ts.tv_nsec;
        }
        int main(void) {
            int frames = 0;
            while (spinner_get_time() < 1.0) {
                uint8_t row[4096];
                spinner_get_image(spinner_line_row(), 1, row, sizeof row);
                double t0 = cpu();
                while (cpu() - t0 < 0.004) {}  /* 4 ms of work */
                spinner_set_speed_and_servo(0.5, 0.0);
                frames++;
            }
            spinner_add_textf("frames %d", frames);
            return 0;
        }
        """))
    plain = drive(str(src), track="floor", time_limit_s=3.0, csv=tmp_path / "a.csv")
    slow = drive(str(src), track="floor", time_limit_s=3.0, mcu_time="measured", mcu_scale=10.0,
                 csv=tmp_path / "b.csv")
    count = lambda r: int(next(t for t in reversed(r.log.data_text) if t).split()[1])  # noqa: E731
    assert plain.outcome == "controller_returned", plain.message
    assert count(plain) >= 45 and count(slow) < 0.7 * count(plain)


def test_camera_free_running_is_charged_as_set_exposure_is():
    """camera_free_running (the kits call it at their init, beside set_exposure) lets the
    controller's time pass first, as every call does (it let none)."""
    def gap(call):
        times = []

        def main(s):
            times.append(s.get_time())
            call(s)
            times.append(s.get_time())

        drive(main, track="floor", time_limit_s=5, mcu_time=0.05)
        return round(times[1] - times[0], 9)

    assert gap(lambda s: s.camera_free_running()) == gap(lambda s: s.set_exposure(0.0195)) == 0.102


FREE_RUNNING_C = """\
    #include <stdio.h>
    #include <time.h>
    #include "spinner.h"
    static double cpu(void) {
        struct timespec ts;
        clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
        return ts.tv_sec + 1e-9 * ts.tv_nsec;
    }
    int main(void) {
        double t0 = spinner_get_time();
        spinner_camera_free_running();
        double t1 = spinner_get_time();
        spinner_set_exposure(0.0195);
        double t2 = spinner_get_time();
        double c0 = cpu();
        while (cpu() - c0 < 0.03) {}  /* 30 ms of work */
        spinner_camera_free_running();
        printf("gaps %.4f %.4f after work %.4f\\n", t1 - t0, t2 - t1, spinner_now() - t2);
        fflush(stdout);
        return 0;
    }
    """


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
@pytest.mark.parametrize("mcu_time", [0.05, "measured"])
def test_a_c_programs_camera_free_running_is_charged_as_its_other_calls(tmp_path, capfd, mcu_time, isolate):
    """spinner_camera_free_running lets the program's time pass first, as spinner_set_exposure
    does: 50 ms a call fixed (it let none: 52 ms between two get_times around it, not 102), the
    measured 30 ms of work before it (it was charged at the next call only)."""
    import dataclasses

    from simrunner.run.native import build_program

    src = tmp_path / "free.c"
    src.write_text(textwrap.dedent(FREE_RUNNING_C))
    prog = dataclasses.replace(build_program([str(src)]), isolate=isolate)
    r = drive(prog, track="floor", time_limit_s=5.0, mcu_time=mcu_time)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    gaps = [float(x) for x in out.split("gaps ")[1].replace("after work", "").split()]
    if mcu_time == 0.05:
        assert gaps == [0.102, 0.102, 0.05], out
    else:
        assert gaps[2] >= 0.028, out  # the work's 30 ms, in whole 2-ms steps


def test_bad_settings_are_one_line_errors():
    with pytest.raises(SettingsError, match=r'mcu_time = \'soon\': expected "measured" or seconds per call'):
        RunSettings(mcu_time="soon")
    with pytest.raises(SettingsError, match=r"mcu_scale = 0: expected a factor in \(0, 10000\]"):
        RunSettings(mcu_scale=0)
    res = CliRunner().invoke(cli, ["drive", "examples/line_follower.py", "--mcu-time", "-1"])
    assert res.exit_code == 2 and "mcu_time = " in res.output and "Traceback" not in res.output


PENDED_C = """\
    #include <stdio.h>
    #include "spinner.h"
    static int calls;
    static void h(void) { calls++; spinner_set_servo(0.1); }
    int main(void) {
        double t0 = spinner_get_time();
        spinner_pend_every(h);   /* unmasked: h runs in it, as NVIC_SetPendingIRQ's handler */
        double t1 = spinner_now();
        spinner_set_servo(0.0);
        double t2 = spinner_now();
        printf("calls %d gaps %.4f %.4f\\n", calls, t1 - t0, t2 - t1);
        fflush(stdout);
        return 0;
    }
    """


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_handler_pended_from_main_may_call_the_spinner(tmp_path, capfd, isolate):
    """spinner_pend_every (a kit's NVIC_SetPendingIRQ) runs the handler in its request, which is
    not charged: the handler's own calls are not charged either, no time passes in a handler;
    main's next call is (the handler's spinner_set_servo was charged as a call of main's,
    inside the handler, and the run ended 'inside an interrupt handler no simulated time passes')."""
    from simrunner.run.native import build_program

    src = tmp_path / "pended.c"
    src.write_text(textwrap.dedent(PENDED_C))
    r = drive(dataclasses.replace(build_program([str(src)]), isolate=isolate), track="floor", time_limit_s=5.0,
              mcu_time=0.05)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    assert "calls 1 gaps 0.0000 0.0500" in out, out
