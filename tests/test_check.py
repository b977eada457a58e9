"""The controller checker (simrunner.run.check): every example passes; each kind of broken
controller gets the problem or warning that names what is wrong."""
from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from simrunner.run.check import check_controller

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="module")
def track():
    from simrunner.run.runner import resolve_track
    from vehicle import CarDescription

    return resolve_track(None, CarDescription())[0]


def write(tmp_path: Path, name: str, body: str) -> Path:
    p = tmp_path / name
    p.write_text(textwrap.dedent(body))
    return p


NOT_CONTROLLERS = {"learn_ppo.py"}  # scripts run with python, not `simrunner drive`
CARS = {"pixy2_follower.py": EXAMPLES / "pixy2_car.toml"}  # controllers of another car than the default


@pytest.mark.parametrize("example", sorted(p.name for p in EXAMPLES.glob("*.py")
                                           if p.name not in NOT_CONTROLLERS))
def test_every_example_controller_passes_the_checker(example, track):
    report = check_controller(EXAMPLES / example, track=track, car=CARS.get(example), seconds=2.0)
    assert report.ok, report.text()
    assert report.sim_time_s > 0.0


def test_a_raising_controller_is_a_problem_with_its_line(tmp_path, track):
    ctrl = write(tmp_path, "boom.py", """\
        def main(s):
            s.get_image()
            x = 1 / 0
        """)
    report = check_controller(ctrl, track=track)
    assert not report.ok
    assert "main raised at boom.py:3: ZeroDivisionError" in report.problems[0]
    assert report.problems[0].count("boom.py:3") == 1  # (was '... division by zero at boom.py:3' too)


def test_an_unseeded_random_controller_is_not_deterministic(tmp_path, track):
    ctrl = write(tmp_path, "rand.py", """\
        import random
        def main(s):
            while True:
                s.get_image(s.line_row)
                s.set_speed_and_servo(1.0, random.uniform(-0.01, 0.01))
        """)
    report = check_controller(ctrl, track=track, seconds=1.0)
    assert any("two runs with the same seed differ" in p and "steer_cmd_rad" in p
               for p in report.problems), report.text()


def test_a_controller_that_never_waits_is_stalled(tmp_path, track):
    ctrl = write(tmp_path, "spin.py", """\
        def main(s):
            while True:
                pass
        """)
    report = check_controller(ctrl, track=track, wall_limit_s=0.5)
    assert any("controller stalled" in p and "(at spin.py:" in p for p in report.problems), report.text()


def test_no_main_is_a_problem(tmp_path, track):
    ctrl = write(tmp_path, "nomain.py", "x = 1\n")
    report = check_controller(ctrl, track=track)
    assert report.problems == (f"{ctrl}: no main(spinner) function defined",)
    typo = write(tmp_path, "typo.py", "def mian(spinner):\n    pass\n\ndef helper():\n    pass\n")
    assert check_controller(typo, track=track).problems == (
        f"{typo}: no main(spinner) function defined (did you mean mian?)",)


def test_warnings_for_a_car_that_never_moves_and_a_main_that_returns(tmp_path, track):
    ctrl = write(tmp_path, "lazy.py", """\
        def main(s):
            for _ in range(10):
                s.get_image()
        """)
    report = check_controller(ctrl, track=track)
    assert report.ok
    assert any("main returned after 0.20 s" in w for w in report.warnings), report.text()
    assert any("no speed was ever commanded" in w for w in report.warnings)


@pytest.mark.parametrize("name, body, kit, said", [
    ("idle.py", "def main(s):\n    while True:\n        s.sleep(0.01)\n", None, "call set_speed or set_speed_and_servo"),
    ("idle.c", '#include "spinner.h"\nint main(void) { for (;;) spinner_sleep(0.01); }\n', None,
     "call spinner_set_speed or spinner_set_speed_and_servo"),
    ("idle.cpp", '#include "spinner.hpp"\nint main() { for (;;) spinner_sleep(0.01); }\n', None,
     "call setSpeed or setSpeedAndServo (spinner.hpp), or spinner_set_speed"),
    ("still.c", '#include "derivative.h"\n#include "TFC/TFC.h"\nint main(void) { TFC_Init(); '
     'TFC_SetMotorPWM(0.4f, 0.4f); for (;;) TFC_Task(); }\n', "tfc",
     "set the motors' duties with TFC_SetMotorPWM after TFC_HBRIDGE_ENABLE")])
def test_a_car_that_never_moves_is_told_the_call_in_its_own_language_and_kit(tmp_path, track, name, body, kit, said):
    """The hint named the Python API's set_speed to a C program and to a TFC firmware whose duties
    the disabled H-bridge kept off; now the program's own language's call, or its kit's."""
    if not name.endswith(".py"):
        import shutil

        if shutil.which("cc") is None or shutil.which("c++") is None:
            pytest.skip("no C/C++ compiler")
        from simrunner.run.native import build_program

        ctrl = build_program([write(tmp_path, name, body)], kit=kit)
    else:
        ctrl = write(tmp_path, name, body)
    report = check_controller(ctrl, track=track, seconds=1.5)
    assert f"no speed was ever commanded: the car does not move ({said})" in report.warnings, report.text()


def test_commands_beyond_the_limits_are_warned(tmp_path, track):
    ctrl = write(tmp_path, "wild.py", """\
        def main(s):
            while True:
                s.get_image(s.line_row)
                s.set_speed_and_servo(50.0, 0.0)
        """)
    report = check_controller(ctrl, track=track, seconds=0.5)
    assert any("exceed the car's max_speed_mps" in w for w in report.warnings), report.text()


def test_check_command_exit_codes(tmp_path):
    from click.testing import CliRunner

    from simrunner.cli import main

    runner = CliRunner()
    ok = runner.invoke(main, ["check", str(EXAMPLES / "line_follower.py"), "--seconds", "1"])
    assert ok.exit_code == 0 and ": OK (two runs, 1.00 s simulated)" in ok.output
    bad = write(tmp_path, "bad.py", "def main(s):\n    s.get_image()\n    1 / 0\n")
    res = runner.invoke(main, ["check", str(bad)])
    assert res.exit_code == 1 and "problem: main raised at bad.py:3: ZeroDivisionError" in res.output
    res = runner.invoke(main, ["check", str(EXAMPLES / "line_follower.py"), "--track", "nope.txt"])
    assert res.exit_code == 2 and "nope.txt: no such track" in res.stderr
