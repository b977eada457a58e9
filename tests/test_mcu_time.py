"""The microcontroller's time (issue 50 item 3, simrunner.run.mcu): --mcu-time makes the
controller's own processing cost simulated time, measured (times --mcu-scale) or fixed."""
from __future__ import annotations

import dataclasses
import inspect
import re
import textwrap
import time
from pathlib import Path

import numpy as np
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
        printf("gaps %.4f %.4f after work %.4f\\n", t1 - t0, t2 - t1, spinner_now_uncharged() - t2);
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


# -- every call is charged, but the documented exemptions (simrunner.run.mcu) -----------------------
REPO = Path(__file__).resolve().parents[1]
INCLUDE = REPO / "simrunner" / "run" / "native" / "include"


def sensor_pixy_car(tmp_path) -> Path:
    """The Pixy2 car with a lidar, a range sensor, encoders and an IMU: every call has its sensor."""
    lidar = (REPO / "examples" / "events" / "lidar_car.toml").read_text().split("[range_sensors.lidar]")[1]
    front = (REPO / "examples" / "events" / "sensor_car.toml").read_text().split("[range_sensors.front]")[1]
    car = tmp_path / "all_car.toml"
    car.write_text((REPO / "examples" / "pixy2_car.toml").read_text() + "\n[range_sensors.lidar]" + lidar
                   + "\n[range_sensors.front]" + front + "\n[encoders]\n[imu]\n")
    return car


def _handler():
    pass


def _every(s, p):
    s.every(10.0, _handler)


def _stop(s, p):
    s.stop_every(_handler)


def _mask(s, p):
    s.disable_interrupts()


def _unmask(s, p):
    s.enable_interrupts()


# The arguments of a Python call of each method, by its own name (its camelCase alias takes the
# same), with what goes before and after it: (setup, args, teardown); setup and teardown take
# (spinner, pixy), args a tuple or a function of the spinner giving one. The charge is measured
# around the call alone.
PY_CALLS = {
    "default_diff_norm": (None, (1.0, 0.1), None),
    "configure": (None, (), None),
    "set_servo": (None, (0.0,), None),
    "set_speed": (None, (0.0,), None),
    "set_motors": (None, (0.0, 0.0), None),
    "set_speed_and_servo": (None, (0.0, 0.0), None),
    "get_image": (None, lambda s: (s.line_row,), None),
    "latest_image": (None, lambda s: (s.line_row,), None),
    "pixy2": (None, (), None),
    "set_exposure": (None, (0.005,), None),
    "camera_free_running": (None, (), None),
    "get_exposure": (None, (), None),
    "get_speed": (None, (), None),
    "get_distance": (None, ("front",), None),
    "get_scan": (None, ("lidar",), None),
    "scan_angles": (None, ("lidar",), None),
    "get_encoder": (None, ("RL",), None),
    "get_gyro": (None, (), None),
    "get_accel": (None, (), None),
    "get_position": (None, (), None),
    "get_time": (None, (), None),
    "sleep": (None, (0.01,), None),
    "every": (None, (10.0, _handler), _stop),
    "stop_every": (_every, (_handler,), None),
    "disable_interrupts": (None, (), _unmask),
    "enable_interrupts": (_mask, (), None),
    "interrupts_disabled": (None, (), None),
    "param": (None, ("x", 1.0), None),
    "add_data": (None, (["x"],), None),
    "add_noise": (None, lambda s: (np.zeros((1, 4), np.uint8),), None),
    # the Pixy2 (pixy = spinner.pixy2()) and its line (pixy.line)
    "init": (None, (), None),
    "change_prog": (None, ("line",), None),
    "get_resolution": (None, (), None),
    "set_camera_brightness": (None, (128,), None),
    "set_lamp": (None, (0, 0), None),
    "get_main_features": (None, (), None),
    "get_all_features": (None, (), None),
    "set_mode": (None, (0,), None),
    "set_next_turn": (None, (0,), None),
    "set_default_turn": (None, (0,), None),
    "set_vector": (None, (0,), None),
    "reverse_vector": (None, (), None),
}
PY_EXEMPT = {"configure", "default_diff_norm", "interrupts_disabled", "pixy2"}  # simrunner.run.mcu
# what the review found not charged (the Pixy2's set_camera_brightness was, through set_exposure)
PY_NEWLY_CHARGED = ("stop_every", "scan_angles", "init", "change_prog", "get_resolution", "set_lamp",
                    "get_main_features", "get_all_features", "set_mode", "set_next_turn", "set_default_turn",
                    "set_vector", "reverse_vector")


def _python_api() -> dict[tuple[str, str], str]:
    """``{(object, name): the method's own name}``: every public method of the Spinner ("s"), the
    Pixy2 ("p") and its line ("line"), and their aliases."""
    from simrunner.run.pixy2 import Pixy2, Pixy2Line
    from simrunner.run.spinner import Spinner

    return {(on, name): fn.__name__ for cls, on in ((Spinner, "s"), (Pixy2, "p"), (Pixy2Line, "line"))
            for name, fn in vars(cls).items() if not name.startswith("_") and inspect.isfunction(fn)}


def _charges(calls, **kw) -> tuple[dict[str, float], dict[str, float]]:
    """Drive the Pixy2 car with sensors (``kw``: mcu_time, ...) calling each ``(object, name)`` of
    ``calls`` (its arguments from PY_CALLS); ``({"object.name": the time charged at it}, {...: the
    time passed from before the work to its return})``, with 30 ms of CPU time before each call
    when measured."""
    charged, passed = {}, {}
    work = kw.get("mcu_time") == "measured"

    def main(s):
        pixy = s.pixy2()
        objs = {"s": s, "p": pixy, "line": pixy.line}
        for (on, name), own in calls.items():
            setup, args, teardown = PY_CALLS[own]
            if setup:
                setup(s, pixy)
            args = args(s) if callable(args) else args
            s.get_time()
            before, t0 = s._s.mcu.charged_s, s._clock.time_s
            if work:
                c0 = time.thread_time()
                while time.thread_time() - c0 < 0.03:  # 30 ms of work
                    pass
            getattr(objs[on], name)(*args)
            key = f"{on}.{name}"
            charged[key], passed[key] = round(s._s.mcu.charged_s - before, 9), round(s._clock.time_s - t0, 9)
            if teardown:
                teardown(s, pixy)

    r = drive(main, track="floor", car=kw.pop("car"), time_limit_s=60, **kw)
    assert r.outcome == "controller_returned", r.message
    return charged, passed


def test_every_python_call_is_charged_but_the_documented_exemptions(tmp_path):
    """Each public method of the Spinner, the Pixy2 and its line (the camelCase aliases too)
    costs the fixed cost, but configure, default_diff_norm, interrupts_disabled and pixy2
    (simrunner.run.mcu.UNCHARGED_METHODS, the reasons there). A new method is charged unless
    listed there; PY_CALLS must give its arguments. (Before: stop_every, scan_angles and the
    Pixy2's calls but set_camera_brightness cost nothing.)"""
    from simrunner.run import mcu

    api = _python_api()
    charged, _ = _charges({k: own for k, own in api.items() if own in PY_CALLS}, car=sensor_pixy_car(tmp_path),
                          mcu_time=0.25)
    wrong = {f"{on}.{name}": got for (on, name), own in api.items() if own in PY_CALLS
             for got in [charged[f"{on}.{name}"]] if got != (0.0 if own in PY_EXEMPT else 0.25)}
    assert not wrong, f"charged (0.25 s expected, none for {sorted(PY_EXEMPT)}): {wrong}"
    missing = set(api.values()) - set(PY_CALLS)
    assert not missing, f"calls without their arguments in PY_CALLS: {missing}"
    assert set(mcu.UNCHARGED_METHODS) == PY_EXEMPT


@pytest.mark.parametrize("mcu_time", [0.05, "measured"])
def test_python_calls_that_were_not_charged_are(tmp_path, mcu_time):
    """stop_every, scan_angles and the Pixy2's calls (pixy.init(), pixy.line.set_mode(0),
    getMainFeatures(), ...): fixed, each costs the 50 ms (it cost nothing); measured, the 30 ms
    of work before it pass there (they passed at the next charged call only)."""
    api = {k: own for k, own in _python_api().items() if own in PY_NEWLY_CHARGED}
    assert set(api.values()) == set(PY_NEWLY_CHARGED)  # (and the C++ names of the Pixy2's)
    charged, passed = _charges(api, car=sensor_pixy_car(tmp_path), mcu_time=mcu_time)
    if mcu_time == 0.05:
        wrong = {name: got for name, got in charged.items() if got != 0.05}
    else:
        wrong = {name: got for name, got in passed.items() if got < 0.028}  # (whole 2-ms steps)
    assert not wrong, wrong


# A C call of each function of spinner.h and pixy2_line.h: (setup, the call, teardown); the
# charge is the time from before the call to spinner_now_uncharged after it (no charge of its own).
C_CALLS = {
    "spinner_configure": ("", "spinner_configure(NULL, NULL, NULL, NULL)", ""),
    "spinner_set_servo": ("", "spinner_set_servo(0.0)", ""),
    "spinner_set_servo_at": ("", "spinner_set_servo_at(0.0, 0.0)", ""),
    "spinner_set_speed": ("", "spinner_set_speed(0.0)", ""),
    "spinner_set_speed_at": ("", "spinner_set_speed_at(0.0, 0.0)", ""),
    "spinner_set_speed_and_servo": ("", "spinner_set_speed_and_servo(0.0, 0.0)", ""),
    "spinner_set_motors": ("", "spinner_set_motors(0.0f, 0.0f)", ""),
    "spinner_get_image": ("", "spinner_get_image(spinner_line_row(), 1, buf, sizeof buf)", ""),
    "spinner_latest_image": ("", "spinner_latest_image(spinner_line_row(), 1, -1, buf, sizeof buf, &n)", ""),
    "spinner_image_width": ("", "spinner_image_width()", ""),
    "spinner_image_height": ("", "spinner_image_height()", ""),
    "spinner_line_row": ("", "spinner_line_row()", ""),
    "spinner_set_exposure": ("", "spinner_set_exposure(0.005)", ""),
    "spinner_set_exposure_next_frame": ("", "spinner_set_exposure_next_frame(0.005)", ""),
    "spinner_get_exposure": ("", "spinner_get_exposure()", ""),
    "spinner_camera_free_running": ("", "spinner_camera_free_running()", ""),
    "spinner_get_speed": ("", "spinner_get_speed()", ""),
    "spinner_get_position": ("", "spinner_get_position(&x, &y, &z)", ""),
    "spinner_get_time": ("", "spinner_get_time()", ""),
    "spinner_now": ("", "spinner_now()", ""),
    "spinner_now_uncharged": ("", "spinner_now_uncharged()", ""),
    "spinner_get_distance": ("", 'spinner_get_distance("front")', ""),
    "spinner_get_scan": ("", 'spinner_get_scan("lidar", rays, 4096)', ""),
    "spinner_get_scan_angles": ("", 'spinner_get_scan_angles("lidar", rays, 4096)', ""),
    "spinner_get_encoder": ("", "spinner_get_encoder(SPINNER_WHEEL_RL)", ""),
    "spinner_get_gyro": ("", "spinner_get_gyro(&x, &y, &z)", ""),
    "spinner_get_accel": ("", "spinner_get_accel(&x, &y, &z)", ""),
    "spinner_encoder_lines": ("", "spinner_encoder_lines(SPINNER_WHEEL_RL, NULL)", ""),
    "spinner_has_imu": ("", "spinner_has_imu()", ""),
    "spinner_sleep": ("", "spinner_sleep(0.01)", ""),
    "spinner_every": ("", "spinner_every(10.0, h)", "spinner_stop_every(h)"),
    "spinner_stop_every": ("spinner_every(10.0, h)", "spinner_stop_every(h)", ""),
    "spinner_stop_every_latched": ("spinner_every(10.0, h)", "spinner_stop_every_latched(h)", ""),
    "spinner_unpend_every": ("spinner_every(10.0, h); spinner_disable_interrupts(); spinner_stop_every_latched(h)",
                             "spinner_unpend_every(h)", "spinner_enable_interrupts()"),
    "spinner_pend_every": ("", "spinner_pend_every(h)", ""),
    "spinner_every_pending": ("spinner_every(10.0, h); spinner_disable_interrupts()", "spinner_every_pending(h)",
                              "spinner_enable_interrupts(); spinner_stop_every(h)"),
    "spinner_has_every": ("", "spinner_has_every(h)", ""),
    "spinner_interrupts": ("", "spinner_interrupts()", ""),
    "spinner_in_interrupt": ("", "spinner_in_interrupt()", ""),
    "spinner_running": ("", "spinner_running()", ""),
    "spinner_disable_interrupts": ("", "spinner_disable_interrupts()", "spinner_enable_interrupts()"),
    "spinner_enable_interrupts": ("spinner_disable_interrupts()", "spinner_enable_interrupts()", ""),
    "spinner_interrupts_disabled": ("", "spinner_interrupts_disabled()", ""),
    "spinner_add_text": ("", "spinner_add_text(lines, 1)", ""),
    "spinner_add_textf": ("", 'spinner_add_textf("%d", 1)', ""),
    "spinner_add_line": ("", "spinner_add_line(buf, 1, 4)", ""),
    "spinner_recording": ("", "spinner_recording()", ""),
    "spinner_add_noise": ("", "spinner_add_noise(buf, 1, 4)", ""),
    "spinner_param": ("", 'spinner_param("x", 1.0)', ""),
    "spinner_fail": None,  # (ends the run: its request OP_FAULT is exempt)
    "spinner_warn": ("", 'spinner_warn("x")', ""),
    "spinner_warn_at": ("", 'spinner_warn_at("x", 0)', ""),
    "pixy2_init": ("", "pixy2_init()", ""),
    "pixy2_change_prog": ("", 'pixy2_change_prog("line")', ""),
    "pixy2_line_get_main_features": ("", "pixy2_line_get_main_features(LINE_ALL_FEATURES, true, &f)", ""),
    "pixy2_line_get_all_features": ("", "pixy2_line_get_all_features(LINE_ALL_FEATURES, true, &f)", ""),
    "pixy2_line_set_mode": ("", "pixy2_line_set_mode(0)", ""),
    "pixy2_line_set_next_turn": ("", "pixy2_line_set_next_turn(0)", ""),
    "pixy2_line_set_default_turn": ("", "pixy2_line_set_default_turn(0)", ""),
    "pixy2_line_set_vector": ("", "pixy2_line_set_vector(0)", ""),
    "pixy2_line_reverse_vector": ("", "pixy2_line_reverse_vector()", ""),
    "pixy2_set_camera_brightness": ("", "pixy2_set_camera_brightness(128)", ""),
    "pixy2_set_lamp": ("", "pixy2_set_lamp(0, 0)", ""),
    "pixy2_get_resolution": ("", "pixy2_get_resolution(&width, &height)", ""),
}
C_EXEMPT = {"spinner_configure", "spinner_image_width", "spinner_image_height", "spinner_line_row",
            "spinner_recording", "spinner_encoder_lines", "spinner_has_imu", "spinner_has_every",
            "spinner_interrupts", "spinner_in_interrupt", "spinner_running", "spinner_interrupts_disabled",
            "spinner_now_uncharged", "spinner_warn", "spinner_warn_at", "spinner_fail", "spinner_stop_every_latched", "spinner_unpend_every",
            "spinner_pend_every", "spinner_every_pending"}  # simrunner.run.mcu.UNCHARGED_C_FUNCTIONS
# what the review found not charged (set_camera_brightness was, through set_exposure)
C_NEWLY_CHARGED = ("spinner_stop_every", "spinner_get_scan_angles", "pixy2_init", "pixy2_change_prog",
                   "pixy2_line_get_main_features", "pixy2_line_get_all_features", "pixy2_line_set_mode",
                   "pixy2_line_set_next_turn", "pixy2_line_set_default_turn", "pixy2_line_set_vector",
                   "pixy2_line_reverse_vector", "pixy2_set_lamp", "pixy2_get_resolution")


def _c_api() -> list[str]:
    """The functions spinner.h and pixy2_line.h declare."""
    return [name for header in ("spinner.h", "pixy2_line.h") for name in re.findall(
        r"^(?!typedef)[A-Za-z_][\w \*]*?\b((?:spinner|pixy2)_\w+)\s*\(", (INCLUDE / header).read_text(), re.M)]


def _c_charges(tmp_path, capfd, names, isolate: bool, mcu_time) -> dict[str, float]:
    """``{name: the time passed from before its call to spinner_now_uncharged after it}`` in a C program
    calling each function of ``names`` (C_CALLS), with 30 ms of CPU time before each when
    measured."""
    from simrunner.run.native import build_program

    body = []
    for name in names:
        setup, call, teardown = C_CALLS[name]
        body.append(f"    {setup}; t0 = spinner_get_time(); work(); {call}; "
                    f'printf("%s %.6f\\n", "{name}", spinner_now_uncharged() - t0); {teardown};')
    src = tmp_path / "calls.c"
    src.write_text(textwrap.dedent("""\
        #include <stdio.h>
        #include <time.h>
        #include "spinner.h"
        #include "pixy2_line.h"
        static void h(void) {}
        static double cpu(void) {
            struct timespec ts;
            clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
            return ts.tv_sec + 1e-9 * ts.tv_nsec;
        }
        static void work(void) {
            if (!WORK) return;
            double c0 = cpu();
            while (cpu() - c0 < 0.03) {}  /* 30 ms of work */
        }
        static uint8_t buf[316 * 208];
        static double rays[4096];
        int main(void) {
            double t0, x, y, z;
            size_t n;
            uint16_t width, height;
            pixy2_line_features f;
            const char *lines[1] = {"x"};
            (void)n, (void)x, (void)y, (void)z, (void)width, (void)height, (void)f, (void)lines;
        """).replace("WORK", "1" if mcu_time == "measured" else "0") + "\n".join(body) + "\n    return 0;\n}\n")
    prog = dataclasses.replace(build_program([str(src)]), isolate=isolate)
    capfd.readouterr()
    r = drive(prog, track="floor", car=sensor_pixy_car(tmp_path), time_limit_s=60, mcu_time=mcu_time)
    text = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, text)
    return {name: float(v) for name, v in (line.split() for line in text.splitlines())}


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_every_c_function_is_charged_but_the_documented_exemptions(tmp_path, capfd, isolate):
    """Each function of spinner.h and pixy2_line.h costs the fixed cost (its request is), but
    those that send none (answered in the program: the car's constants, its own state, the PRIMASK
    read) and spinner_now_uncharged, spinner_warn, spinner_fail and the kits' NVIC functions, whose
    requests are exempt (simrunner.run.mcu, the reasons there). A new function must have its call in
    C_CALLS. (Before: spinner_stop_every, spinner_get_scan_angles and the Pixy2's calls but
    pixy2_set_camera_brightness cost nothing; spinner_now was exempt, so a loop polling it let no
    time pass.)"""
    from simrunner.run import mcu

    api = _c_api()
    assert set(api) == set(C_CALLS), f"C_CALLS misses {set(api) - set(C_CALLS)}, has more {set(C_CALLS) - set(api)}"
    passed = _c_charges(tmp_path, capfd, [name for name in api if C_CALLS[name]], isolate, 0.25)
    wrong = {name: got for name, got in passed.items()
             if (got != 0.0 if name in C_EXEMPT else not 0.25 <= got < 0.3)}  # (its own wait: < 50 ms)
    assert not wrong, f"time passed at the call (0.25 s and its own time expected, none for the exempt): {wrong}"
    assert set(mcu.UNCHARGED_C_FUNCTIONS) == C_EXEMPT


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
@pytest.mark.parametrize("mcu_time", [0.05, "measured"])
def test_c_functions_that_were_not_charged_are(tmp_path, capfd, mcu_time, isolate):
    """spinner_stop_every, spinner_get_scan_angles and pixy2_line.h's calls: fixed, each costs the
    50 ms (none); measured, the 30 ms of work before it pass there (they passed at the next charged
    call only: spinner_now_uncharged after it read the time before the work)."""
    passed = _c_charges(tmp_path, capfd, C_NEWLY_CHARGED, isolate, mcu_time)
    low = 0.05 if mcu_time == 0.05 else 0.028  # (measured: whole 2-ms steps)
    wrong = {name: got for name, got in passed.items() if got < low}
    assert not wrong and len(passed) == len(C_NEWLY_CHARGED), passed


PENDED_C = """\
    #include <stdio.h>
    #include "spinner.h"
    static int calls;
    static void h(void) { calls++; spinner_set_servo(0.1); }
    int main(void) {
        double t0 = spinner_get_time();
        spinner_pend_every(h);   /* unmasked: h runs in it, as NVIC_SetPendingIRQ's handler */
        double t1 = spinner_now_uncharged();
        spinner_set_servo(0.0);
        double t2 = spinner_now_uncharged();
        printf("calls %d gaps %.4f %.4f\\n", calls, t1 - t0, t2 - t1);
        fflush(stdout);
        return 0;
    }
    """


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_handler_pended_from_main_may_call_the_spinner(tmp_path, capfd, isolate):
    """spinner_pend_every (a kit's NVIC_SetPendingIRQ) runs the handler in its request (exempt,
    the kits' NVIC emulation): the handler's own calls are not charged, no time passes in a
    handler; main's next call is (the handler's spinner_set_servo was charged as a call of main's,
    inside the handler, and the run ended 'inside an interrupt handler no simulated time passes')."""
    from simrunner.run.native import build_program

    src = tmp_path / "pended.c"
    src.write_text(textwrap.dedent(PENDED_C))
    r = drive(dataclasses.replace(build_program([str(src)]), isolate=isolate), track="floor", time_limit_s=5.0,
              mcu_time=0.05)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    assert "calls 1 gaps 0.0000 0.0500" in out, out


COMMAND_RACE_C = """\
    #include <stdio.h>
    #include "spinner.h"
    static int calls;
    static void h(void) { calls++; spinner_set_speed_and_servo(1.0, 0.3); spinner_stop_every(h); }
    int main(void) {
        spinner_every(0.04, h);
        spinner_set_speed_and_servo(1.0, 0.0);  /* --mcu-time 0.05: h falls due in its charge */
        spinner_sleep(0.2);
        printf("calls %d\\n", calls);
        fflush(stdout);
        return 0;
    }
    """


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_a_command_charged_after_a_handler_keeps_its_own_yaw_rate(tmp_path, capfd, isolate):
    """A C command's charge comes before the command is read: a handler that falls due in it and
    commands (1 m/s, 0.3 rad) leaves main's command (1 m/s, 0 rad) with its own yaw rate, 0 (the
    command was read first, the handler's yaw rate then taken for it: steering 0 with 1.7 rad/s)."""
    from simrunner.run.native import build_program

    src = tmp_path / "race.c"
    src.write_text(textwrap.dedent(COMMAND_RACE_C))
    r = drive(dataclasses.replace(build_program([str(src)]), isolate=isolate), track="floor", time_limit_s=5.0,
              mcu_time=0.05, csv=tmp_path / "run.csv")
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned" and "calls 1" in out, (r.message, out)
    assert r.log.steer_cmd_rad[-1] == 0.0 and r.log.yaw_rate_cmd_radps[-1] == 0.0, r.log.yaw_rate_cmd_radps[-5:]


CPP_MEMBERS = """\
    #include <cstdio>
    #include "spinner.hpp"
    #include "Pixy2.h"
    static void h() {}
    int main() {
        Spinner s;
        Pixy2 pixy;
        double t0 = s.getTime();
        pixy.init();
        double t1 = spinner_now_uncharged();
        pixy.getResolution();
        double t2 = spinner_now_uncharged();
        pixy.line.setMode(0);
        double t3 = spinner_now_uncharged();
        s.every(10.0, h);
        double t4 = spinner_now_uncharged();
        s.stopEvery(h);
        double t5 = spinner_now_uncharged();
        s.getScanAngles("lidar");
        double t6 = spinner_now_uncharged();
        s.interruptsDisabled();
        double t7 = spinner_now_uncharged();
        std::printf("frame %d %d gaps %.4f %.4f %.4f %.4f %.4f %.4f %.4f\\n", pixy.frameWidth, pixy.frameHeight,
                    t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4, t6 - t5, t7 - t6);
        std::fflush(stdout);
        return 0;
    }
    """


@pytest.mark.parametrize("isolate", [False, True], ids=["in-process", "isolate"])
def test_cpp_members_are_charged_as_the_c_calls_they_make(tmp_path, capfd, isolate):
    """Pixy2.h's init and getResolution (each one request: getResolution read the frame's size in
    the program, init did too after its request) and line.setMode, spinner.hpp's every, stopEvery
    and getScanAngles cost 50 ms each; interruptsDisabled (PRIMASK) nothing."""
    from simrunner.run.native import build_program

    src = tmp_path / "members.cpp"
    src.write_text(textwrap.dedent(CPP_MEMBERS))
    r = drive(dataclasses.replace(build_program([str(src)]), isolate=isolate), track="floor",
              car=sensor_pixy_car(tmp_path), time_limit_s=5.0, mcu_time=0.05)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    assert "frame 316 208 gaps 0.0500 0.0500 0.0500 0.0500 0.0500 0.0500 0.0000" in out, out


# -- a handler's own time (measured: charged at main's next call; fixed: nothing), C and Python alike --

HANDLER_BURN_PY = """\
import time


def main(s):
    burned = []

    def handler():
        c0 = time.thread_time()
        while time.thread_time() - c0 < 0.010:  # 10 ms of the handler's own work
            pass
        burned.append(time.thread_time() - c0)
        s.stop_every(handler)

    s.every(0.02, handler)
    s.sleep(0.02)          # the handler runs at 0.020 s, inside this wait
    t = s.get_time()       # main's next call: the handler's time passes first
    print(f"handler burned {burned[0]:.6f} get_time {t:.6f}", flush=True)
"""

HANDLER_BURN_C = """\
#include <stdio.h>
#include <time.h>
#include "spinner.h"
static double burned;
static double cpu(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}
static void handler(void) {
    double c0 = cpu();
    while (cpu() - c0 < 0.010) {}   /* 10 ms of the handler's own work */
    burned = cpu() - c0;
    spinner_stop_every(handler);
}
int main(void) {
    spinner_every(0.02, handler);
    spinner_sleep(0.02);            /* the handler runs at 0.020 s, inside this wait */
    double t = spinner_get_time();  /* main's next call: the handler's time passes first */
    printf("handler burned %.6f get_time %.6f\\n", burned, t);
    fflush(stdout);
    return 0;
}
"""


def _handler_burn(tmp_path, capfd, language: str, **kw) -> tuple[float, float]:
    """``(the handler's CPU seconds, main's get_time after it)`` of HANDLER_BURN_* in ``language``."""
    src = tmp_path / ("burn.py" if language == "python" else "burn.c")
    src.write_text(HANDLER_BURN_PY if language == "python" else HANDLER_BURN_C)
    capfd.readouterr()
    r = drive(str(src), track="floor", time_limit_s=5.0, **kw)
    out = capfd.readouterr().out
    assert r.outcome == "controller_returned", (r.message, out)
    got = re.search(r"handler burned ([0-9.]+) get_time ([0-9.]+)", out)
    assert got, out
    return float(got.group(1)), float(got.group(2))


@pytest.mark.parametrize("language", ["python", "c"])
def test_measured_a_handlers_cpu_time_is_charged_at_mains_next_call(tmp_path, capfd, language):
    """A handler burning 10 ms of CPU at 0.020 s, --mcu-scale 2: main's get_time after the wait reads
    0.020 + about 20 ms + its own 2-ms step, C and Python alike (Python's handler's time was not
    charged: 0.022, as without --mcu-time). The charge is whole 2-ms steps, the rest carried."""
    burned, t = _handler_burn(tmp_path, capfd, language, mcu_time="measured", mcu_scale=2.0)
    shift = t - 0.022
    assert burned >= 0.010 and burned * 2 - 0.0021 <= shift <= burned * 2 + 0.004, (burned, t)
    _, plain = _handler_burn(tmp_path, capfd, language)
    assert plain == pytest.approx(0.022)


def test_with_a_fixed_cost_a_handler_costs_nothing_in_c_and_python_alike(tmp_path, capfd):
    """--mcu-time 0.001: the handler's work and its call (stop_every) are not charged; main's calls
    are (every, sleep, get_time: 3 ms, a step of it carried) - the same time in both languages."""
    times = [_handler_burn(tmp_path, capfd, language, mcu_time=0.001)[1] for language in ("python", "c")]
    assert times == [pytest.approx(0.024)] * 2, times


def test_measured_a_python_handlers_spinner_calls_are_not_its_time():
    """The simulator's work in a handler's Spinner calls (20 latest_image renders, over 100 ms of
    CPU here) is not the handler's time: at --mcu-scale 20 main's next call moves by its own step and
    the handler's few lines only (charged, the renders alone would be seconds)."""
    got = {}

    def main(s):
        def handler():
            c0 = time.thread_time()
            for _ in range(20):
                s.latest_image(-1)
            got["calls_s"] = time.thread_time() - c0
            s.stop_every(handler)

        s.every(0.02, handler)
        s.sleep(0.02)
        got["t"] = s.get_time()

    r = drive(main, track="floor", time_limit_s=5.0, mcu_time="measured", mcu_scale=20.0)
    assert r.outcome == "controller_returned", r.message
    assert got["calls_s"] * 20 > 0.2, got  # (what charging them would have cost)
    assert got["t"] <= 0.022 + 0.010, got
