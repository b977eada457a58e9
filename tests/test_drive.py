"""`simrunner drive`: the real sim on real tracks, faults, CLI, determinism, examples."""
from __future__ import annotations

import dataclasses
import json
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.run.runner import default_track, drive
from simrunner.telemetry.log import COLUMN_NAMES, EXTRA_COLUMNS, read_log
from vehicle.description import CarDescription

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
SHARED_TRACKS = Path(__file__).resolve().parents[2] / "shared" / "tracks"


def write(tmp_path: Path, name: str, body: str) -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(body))
    return path


def run_cli(*args: str):
    return CliRunner().invoke(cli, ["drive", *map(str, args)])


def test_default_track_is_the_bundled_copy_of_the_example_layout():
    assert default_track().is_file()
    assert default_track().read_text() == (EXAMPLES / "thesis_figure8.txt").read_text()


def test_line_follower_completes_a_lap_of_the_default_track(tmp_path):
    r = drive(EXAMPLES / "line_follower.py", laps=1, csv=tmp_path / "t.csv",
              summary=tmp_path / "s.json", plot=tmp_path / "p.png")
    assert r.outcome == "finished" and r.laps_completed == 1
    assert 5.0 < r.lap_times_s[0] < 20.0
    summary = json.loads((tmp_path / "s.json").read_text())
    for key in ("outcome", "laps_completed", "lap_times_s", "sim_time_s", "wall_time_s",
                "real_time_factor", "track", "seed"):
        assert key in summary
    assert summary["outcome"] == "finished" and summary["seed"] == 0
    data = read_log(tmp_path / "t.csv")
    # every column of the schema but the extra ones (a flat track, a car without encoders or IMU)
    assert data.names == tuple(n for n in COLUMN_NAMES if n not in EXTRA_COLUMNS)
    assert len(data) == len(r.log)
    np.testing.assert_allclose(data.x_m, r.log.x_m, rtol=0, atol=5e-7)  # the file: the log, %.6f
    assert data.t_s[1] - data.t_s[0] == pytest.approx(0.02)  # one row per camera frame
    assert data.lap[-1] == 1 and not data.off_track.any()
    assert any("steer" in text for text in data.data_text)  # the controller's add_data text
    assert (tmp_path / "p.png").stat().st_size > 10_000


@pytest.mark.parametrize("name", ["nxp_raceway", "nxp_raceway_octagon"])
def test_line_follower_completes_a_lap_of_the_nxp_tracks(name):
    folder = SHARED_TRACKS / name
    if not folder.is_dir():
        pytest.skip(f"{folder} not present (shared NXP tracks live beside the checkout)")
    r = drive(EXAMPLES / "line_follower.py", track=folder, laps=1)
    assert r.outcome == "finished", r.message
    assert r.laps_completed == 1


def test_same_inputs_and_seed_give_identical_csv_bytes(tmp_path):
    for name in ("a.csv", "b.csv"):
        drive(EXAMPLES / "line_follower.py", time_limit_s=2.0, seed=7, csv=tmp_path / name)
    a, b = (tmp_path / "a.csv").read_bytes(), (tmp_path / "b.csv").read_bytes()
    assert a == b and a.count(b"\n") == 103  # format line, header, frames 0..100
    # the seed drives the camera noise: the default line camera's is below a grey level, so
    # a camera with a noisier read-out (2.5 grey levels) shows it in the controller's log
    base = CarDescription()
    noisy = base.replace(camera=dataclasses.replace(base.camera, dark_noise_e=60000.0))
    for name, seed in (("n7.csv", 7), ("n8.csv", 8)):
        drive(EXAMPLES / "line_follower.py", car=noisy, time_limit_s=2.0, seed=seed, csv=tmp_path / name)
    assert (tmp_path / "n7.csv").read_bytes() != (tmp_path / "n8.csv").read_bytes()


def test_controller_that_raises(tmp_path):
    ctrl = write(tmp_path, "crashy.py", """\
        def helper(s):
            return 1 / 0

        def main(s):
            s.set_speed_and_servo(0.5, 0.0)
            for _ in range(20):
                s.get_image()
            helper(s)
        """)
    res = run_cli(ctrl, "--csv", tmp_path / "t.csv", "--video", tmp_path / "v.mp4",
                  "--summary", tmp_path / "s.json")
    assert res.exit_code == 1
    err = res.stderr
    assert f'File "{ctrl.resolve()}", line 8, in main' in err
    assert f'File "{ctrl.resolve()}", line 2, in helper' in err
    assert "ZeroDivisionError: division by zero" in err
    assert "simrunner" not in err.replace(str(ctrl.resolve()), "")  # no runner frames
    data = read_log(tmp_path / "t.csv")
    assert data.frame[-1] == 20  # rows up to the fault
    assert (tmp_path / "v.mp4").stat().st_size > 0
    assert json.loads((tmp_path / "s.json").read_text())["outcome"] == "controller_error"


def test_nan_command_is_a_clear_error(tmp_path):
    ctrl = write(tmp_path, "nan.py", """\
        def main(s):
            s.get_image()
            s.set_speed(float("nan"))
        """)
    r = drive(ctrl, csv=tmp_path / "t.csv")
    assert r.outcome == "controller_error"
    assert "set_speed(speed=nan): expected a finite number" in r.message
    assert 'line 3, in main' in r.error.traceback_text
    assert len(read_log(tmp_path / "t.csv")) == 2


def test_controller_cannot_swallow_the_end_of_the_run(tmp_path):
    ctrl = write(tmp_path, "greedy.py", """\
        def main(s):
            while True:
                try:
                    s.sleep(0.1)
                except Exception:
                    pass
        """)
    r = drive(ctrl, time_limit_s=1.0)
    assert r.outcome == "timeout" and r.sim_time_s == pytest.approx(1.0)


def test_never_waiting_controller_is_stopped_by_the_watchdog(tmp_path):
    ctrl = write(tmp_path, "spin.py", """\
        def main(s):
            s.get_image()
            x = 0
            while True:
                x += 1
        """)
    res = run_cli(ctrl, "--wall-limit", "0.5", "--csv", tmp_path / "t.csv")
    assert res.exit_code == 1
    assert "outcome: stalled" in res.output
    assert re.search(r"at spin\.py:[45] in main", res.output)
    assert (tmp_path / "t.csv").is_file()


@pytest.mark.parametrize("body, expected", [
    (None, "no such controller file"),
    ("def main(s)\n    pass\n", ":1: syntax error"),
    ("x = 1\n", "no main(spinner) function"),
    ("def main():\n    pass\n", "main must take one argument"),
])
def test_bad_controller_file_is_one_line_without_traceback(tmp_path, body, expected):
    ctrl = tmp_path / "ctrl.py"
    if body is not None:
        ctrl.write_text(body)
    res = run_cli(ctrl, "--csv", tmp_path / "t.csv")
    assert res.exit_code == 2
    assert expected in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr
    assert not (tmp_path / "t.csv").exists()


@pytest.mark.parametrize("name", ["controller.txt", "controller", "controller.PY"])
def test_a_controller_of_another_kind_is_named_as_such(tmp_path, name):
    """A lone file neither Python nor C/C++ was told 'several files, -I, -D, --kit and --isr
    are for C/C++ controllers', as if C options had been given."""
    ctrl = tmp_path / name
    ctrl.write_text("def main(s):\n    pass\n")
    res = run_cli(ctrl)
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert f"{name}: expected a Python controller (.py) or a C/C++ one (.c, .cpp sources or one .so)" in res.stderr
    assert "several files" not in res.stderr


def test_bad_track_is_one_line(tmp_path):
    ctrl = write(tmp_path, "c.py", "def main(s):\n    pass\n")
    res = run_cli(ctrl, "--track", tmp_path / "nope.txt")
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1


def test_main_returning_ends_the_run_with_exit_0(tmp_path):
    ctrl = write(tmp_path, "ret.py", """\
        def main(s):
            s.set_speed_and_servo(1.0, 0.0)
            s.sleep(0.5)
        """)
    res = run_cli(ctrl)
    assert res.exit_code == 0, res.output
    assert "outcome: controller_returned" in res.output


def test_driving_off_the_track_ends_the_run(tmp_path):
    ctrl = write(tmp_path, "off.py", """\
        def main(s):
            s.set_speed_and_servo(1.5, 0.4)  # tight left circle from the crossroads
            while True:
                s.get_image()
        """)
    # the car starts before the crossroads: turning left there leaves the course first
    r = drive(ctrl, time_limit_s=10.0)
    assert r.outcome == "off_course" and r.message.startswith("turned at CROSSROADS (piece 0, line 7)")
    # from the start gate of a plain oval it leaves the road: 3 wheels off end the run
    # (the rules), 1 wheel with the strict rule, earlier; the first wheel off is a warning
    oval = Path(__file__).resolve().parents[1] / "examples" / "kit_S.txt"
    rules = drive(ctrl, track=oval, time_limit_s=10.0)
    strict = drive(ctrl, track=oval, time_limit_s=10.0, off_track_wheels=1)
    assert rules.outcome == strict.outcome == "off_track"
    assert strict.sim_time_s < rules.sim_time_s < 5.0
    assert any("fewer than 3 wheels off the road" in w for w in rules.warnings)
    assert not strict.warnings


def test_callable_controller_and_thesis_style_spinner_constructor():
    from simrunner import Spinner

    seen = {}

    def main(spinner):
        s = Spinner(turn_norm=lambda speed, angle: -angle / 512 * 0.4)  # attaches to the run
        s.setSpeedAndServo(0.5, 0)
        seen["t"] = s.getTime()

    r = drive(main, time_limit_s=1.0)
    assert r.outcome == "controller_returned" and seen["t"] == pytest.approx(0.002)


def test_real_car_units_example_laps_the_default_track():
    r = drive(EXAMPLES / "real_car_units.py")
    assert r.outcome == "finished", r.message
    assert r.lap_times_s[0] > 6.5  # the full figure-8, not a shortcut through the crossroads


@pytest.mark.parametrize("example", ["camera_row_test.py", "velocity_test.py"])
def test_thesis_examples_run(example, tmp_path):
    r = drive(EXAMPLES / example, csv=tmp_path / "t.csv")
    assert r.outcome == "controller_returned", r.message


def test_csv_row_k_records_the_command_set_in_answer_to_frame_k(tmp_path):
    """Row k = state at t_k and the command set at t_k (in force from t_k on), the same
    convention as `simrunner excite --simulate` logs and `simrunner gap` reads."""
    def main(s):
        for k in range(1, 30):
            s.get_image(s.line_row)          # frame k
            s.set_speed_and_servo(0.01 * k, 0.001 * k)

    res = drive(main, time_limit_s=2.0, csv=tmp_path / "c.csv")
    log = read_log(tmp_path / "c.csv")
    assert res.outcome == "controller_returned"
    k = log.frame
    assert log.speed_cmd_mps[0] == 0.0                      # nothing set before the first step
    sel = (k >= 1) & (k < 29)
    assert list(log.speed_cmd_mps[sel]) == pytest.approx(list(0.01 * k[sel]), abs=1e-6)
    assert list(log.steer_cmd_rad[sel]) == pytest.approx(list(0.001 * k[sel]), abs=1e-6)
