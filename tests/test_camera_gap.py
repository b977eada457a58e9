"""simrunner calibrate-camera: recorded lines read with one-line errors, each camera effect found
on lines our own camera recorded with that effect (and none on the car file's own camera), the
outputs a team reads."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.workflows.calibration.camera_fit import (calibrate_straight, predicted,
                                                        record_straight)
from simrunner.workflows.calibration.camera_lines import Recording, read_recordings
from simrunner.workflows.calibration.measured import CalibrationError
from vehicle.description import CarDescription, load_car

CAR = CarDescription()
IDEAL = CAR.replace(camera=dataclasses.replace(CAR.camera, model="ideal"))


def camera(**kw) -> CarDescription:
    return CAR.replace(camera=dataclasses.replace(CAR.camera, **kw))


def fit_of(true_car, model_car=CAR, *, frames=60, offset_m=0.03, seed=1):
    lines = record_straight(true_car, frames, offset_m=offset_m, seed=seed)
    rec = Recording(lines, tuple(f"rec.csv:{i + 1}" for i in range(frames)), None, None, (0,))
    return calibrate_straight(rec, model_car)


@pytest.mark.parametrize("true_car, model_car", [(CAR, CAR), (IDEAL, IDEAL)], ids=["linescan", "ideal"])
def test_the_car_files_own_camera_shows_no_effect(true_car, model_car):
    fit = fit_of(true_car, model_car, offset_m=-0.05, seed=4)
    assert fit.effects == [] and not fit.unexplained
    assert fit.nuisance["offset_m"] == pytest.approx(-0.05, abs=0.004)
    assert fit.nuisance["scale"] == pytest.approx(1.0, abs=0.03)


@pytest.mark.parametrize("name, injected", [
    ("black_level", dict(black_level_dn=20.0)),
    ("vignetting", dict(vignetting_power=6.0)),
    ("blur", dict(psf_sigma_px=2.0)),
    ("gain", dict(analog_gain=0.6)),
    ("startup_frames", dict(startup_frames=3)),
    ("noise", dict(dark_noise_e=60000.0)),
    ("fixed_pattern", dict(prnu=0.10)),
])
def test_one_injected_effect_is_named_with_its_value(name, injected):
    """The fitted value against the truth's (the injected camera's own mean-line parameters,
    frame counts, noise in grey levels, gain pattern), within 12 %."""
    truth = camera(**injected)
    fit = fit_of(truth)
    assert fit.effects == [name], (fit.effects, fit.parameters)
    pred = predicted(truth)
    # the gain pattern this camera has in its line row, where the lane lies (its seeded draw)
    row_gains = np.random.default_rng(truth.camera.fixed_pattern_seed).standard_normal((128, 128))[60]
    want = {"noise": pred["noise_dn"], "fixed_pattern": 0.10 * row_gains[30:90].std()}.get(name, pred.get(name))
    assert fit.parameters[name] == pytest.approx(want, rel=0.12)
    assert fit.hints[name]


def test_saturation_dead_and_hot_pixels_are_found():
    fit = fit_of(camera(exposure_s=0.045))
    assert "saturation" in fit.effects and fit.parameters["saturation"] > 0.3
    assert "clipped at 255: shorten the exposure" in fit.hints["saturation"]
    fit = fit_of(camera(dead_pixels=600, hot_pixels=600))
    assert {"dead_pixels", "hot_pixels"} <= set(fit.effects)
    assert fit.car_after.camera.dead_pixels == round(fit.parameters["dead_pixels"] * 128)


def test_the_fitted_camera_records_the_line_the_car_recorded():
    truth = camera(black_level_dn=18.0)
    fit = fit_of(truth)
    assert fit.effects == ["black_level"] and fit.rmse_after < 0.6 * fit.rmse_before
    assert fit.car_after.camera.black_level_dn == pytest.approx(18.0, abs=1.5)
    again = fit_of(truth, fit.car_after, seed=9)  # the fitted car: nothing left to name
    assert again.effects == []


def _write(path, rows, header=None):
    text = "" if header is None else header + "\n"
    path.write_text(text + "\n".join(",".join(str(v) for v in row) for row in rows) + "\n")
    return path


def test_cli_writes_report_car_and_plot(tmp_path):
    lines = record_straight(camera(vignetting_power=6.5), 50, offset_m=0.02, seed=3)
    a = _write(tmp_path / "a.csv", lines[:25].astype(int))
    b = _write(tmp_path / "b.csv", np.column_stack([np.arange(25) * 0.02, lines[25:].astype(int)]),
               header="t_s," + ",".join(f"p{i}" for i in range(128)))
    res = CliRunner().invoke(cli, ["calibrate-camera", str(a), str(b), "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert "vignetting: the ends of the line fall off as cos^6" in res.output
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["effects"] == ["vignetting"] and report["rmse_after"] < report["rmse_before"]
    assert report["recordings"] == [str(a), str(b)]
    car = load_car(tmp_path / "out" / "car.toml")
    assert car.camera.vignetting_power == pytest.approx(6.5, abs=0.4)
    assert "simrunner calibrate-camera" in (tmp_path / "out" / "car.toml").read_text()
    assert (tmp_path / "out" / "lines.png").stat().st_size > 10_000


@pytest.mark.parametrize("body, message", [
    ("", "no recorded lines (empty file)"),
    ("1," * 126 + "1\n", ":1: 127 values, expected 128 (one per pixel of camera.width_px = 128)"),
    ("\n".join(",".join(["7"] * 40 + ["abc"] + ["9"] * 87) for _ in range(2)), ":1: 'abc' in column 41 is not a number"),
    (",".join(str(i) for i in range(128)) + "\n" + ",".join(["50"] * 128) + "\n",
     ":2: every pixel reads 50: not a camera line"),
    (",".join(["300"] + ["5"] * 127) + "\n", ":1: 300 at pixel 0: expected a whole number 0..255"),
    ("t_s,p0,p1\n0,1,2\n", ":1: header without p2, p3, p4 ...: expected columns p0 .. p127"),
])
def test_bad_recordings_are_one_line_errors_and_write_nothing(tmp_path, body, message):
    path = tmp_path / "lines.csv"
    path.write_text(body)
    with pytest.raises(CalibrationError) as err:
        read_recordings([path], 128)
    assert str(err.value).startswith(str(path)) and message in str(err.value)
    res = CliRunner().invoke(cli, ["calibrate-camera", str(path), "-o", str(tmp_path / "out")])
    assert res.exit_code == 2 and message in res.output and "Traceback" not in res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


def test_power_up_frames_lead_a_file_and_are_skipped(tmp_path):
    lines = record_straight(camera(startup_frames=2), 30, seed=5).astype(int)
    rec = read_recordings([_write(tmp_path / "l.csv", lines)], 128)
    assert (rec.frames[:2] == 255).all()
    fit = calibrate_straight(rec, CAR)
    assert fit.parameters["startup_frames"] == 2.0 and fit.frames_used == 28


def test_two_effects_that_trade_for_each_other_are_both_found():
    """A raised black level and a stronger fall-off can each be half-mimicked by a gain change;
    scoring the effects together finds the two that are there."""
    truth = camera(black_level_dn=20.0, vignetting_power=5.0)
    fit = fit_of(truth, offset_m=0.04, seed=2)
    assert fit.effects == ["black_level", "vignetting"], fit.effects
    assert fit.parameters["black_level"] == pytest.approx(predicted(truth)["black_level"], rel=0.1)
    assert fit.parameters["vignetting"] == pytest.approx(5.0, rel=0.1)


# -- --scene track: lines recorded while driving, with poses ---------------------------------
@pytest.fixture(scope="module")
def track_poses():
    from simrunner.run.runner import default_track
    from simrunner.track.load import load_track

    track = load_track(default_track())
    cl = np.asarray(track.centreline)
    rng = np.random.default_rng(0)
    idx = np.linspace(0, len(cl) - 2, 100).astype(int)
    d = cl[idx + 1] - cl[idx]
    yaw = np.arctan2(d[:, 1], d[:, 0]) + rng.normal(0, 0.05, len(idx))
    off = rng.normal(0, 0.05, len(idx))
    pts = cl[idx] + np.column_stack((-np.sin(yaw), np.cos(yaw))) * off[:, None]
    return track, np.column_stack((pts, yaw))


@pytest.mark.parametrize("truth, effects", [(CAR, []), (camera(black_level_dn=20.0), ["black_level"]),
                                            (camera(startup_frames=3), ["startup_frames"])])
def test_track_scene_names_what_differs(track_poses, truth, effects):
    from simrunner.workflows.calibration.camera_track import calibrate_track, record_track

    track, poses = track_poses
    lines = record_track(truth, track, poses, seed=1)
    rec = Recording(lines, tuple(f"t.csv:{i + 2}" for i in range(len(lines))), None, poses, (0,))
    fit = calibrate_track(rec, CAR, track)
    assert fit.effects == effects and fit.scene == "track" and not fit.unexplained
    if effects == ["black_level"]:
        assert fit.parameters["black_level"] == pytest.approx(predicted(truth)["black_level"], rel=0.1)


def test_track_scene_cli_and_its_input_errors(tmp_path, track_poses):
    from simrunner.run.runner import default_track
    from simrunner.workflows.calibration.camera_track import record_track

    track, poses = track_poses
    lines = record_track(camera(vignetting_power=6.0), track, poses[:60], seed=2).astype(int)
    header = "x_m,y_m,yaw_rad," + ",".join(f"p{i}" for i in range(128))
    rows = [",".join([f"{x:.5f}", f"{y:.5f}", f"{t:.5f}"] + [str(v) for v in line])
            for (x, y, t), line in zip(poses[:60], lines)]
    (tmp_path / "drive.csv").write_text(header + "\n" + "\n".join(rows) + "\n")
    res = CliRunner().invoke(cli, ["calibrate-camera", str(tmp_path / "drive.csv"), "--scene", "track",
                                   "--track", str(default_track()), "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "out" / "report.json").read_text())["effects"] == ["vignetting"]
    res = CliRunner().invoke(cli, ["calibrate-camera", str(tmp_path / "drive.csv"), "--scene", "track",
                                   "-o", str(tmp_path / "o2")])
    assert res.exit_code == 2 and "--scene track needs --track" in res.output
    _write(tmp_path / "plain.csv", lines[:20])
    res = CliRunner().invoke(cli, ["calibrate-camera", str(tmp_path / "plain.csv"), "--scene", "track",
                                   "--track", str(default_track()), "-o", str(tmp_path / "o3")])
    assert res.exit_code == 2 and "needs the car's pose with every line" in res.output


def test_the_fitted_car_gives_the_controller_the_recorded_line(tmp_path):
    """The issue's promise: 200 lines of a 'real' camera standing on a straight, one command,
    and the simulator's camera (the written car.toml) then gives the same line there."""
    real = camera(black_level_dn=15.0, vignetting_power=5.0, prnu=0.06)
    lines = record_straight(real, 200, offset_m=0.05, seed=11)
    path = _write(tmp_path / "real.csv", lines.astype(int))
    res = CliRunner().invoke(cli, ["calibrate-camera", str(path), "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    fitted = load_car(tmp_path / "out" / "car.toml")
    recorded = lines[1:].mean(axis=0)
    before = record_straight(CAR, 40, offset_m=0.05, seed=12)[1:].mean(axis=0)
    after = record_straight(fitted, 40, offset_m=0.05, seed=12)[1:].mean(axis=0)
    rmse = lambda a, m=slice(None): float(np.sqrt(np.mean((a - recorded)[m] ** 2)))  # noqa: E731
    assert rmse(after) < 0.5 * rmse(before), (rmse(before), rmse(after))
    # on the lane, where each pixel's own gain was measured, the line is the recorded one; at the
    # lane's edges the pixels' gains are not measured (the edge moves when the car does)
    lane = np.zeros(128, bool)
    lane[25:90] = True
    assert rmse(after, lane) < 1.5 < 0.25 * rmse(before, lane), (rmse(before, lane), rmse(after, lane))
