"""simrunner calibrate's camera procedures (dark frame, flat field, exposure sweep) on lines our
own camera recorded with known numbers: each finds its numbers back; bad files are one line."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.workflows.calibration.calibrate import calibrate, load_measurements
from simrunner.workflows.calibration.camera_fit import _expected_defects, record_uniform
from simrunner.workflows.calibration.measured import CalibrationError
from vehicle.description import CarDescription, load_car

CAR = CarDescription()


def camera(**kw) -> CarDescription:
    return CAR.replace(camera=dataclasses.replace(CAR.camera, **kw))


def save(path, frames):
    np.savetxt(path, frames, fmt="%d", delimiter=",")
    return path.name


def test_dark_frame_gives_black_level_dsnu_and_hot_pixels(tmp_path):
    truth = camera(black_level_dn=12.0, dsnu_e=120000.0, dark_noise_e=50000.0, hot_pixels=640)
    name = save(tmp_path / "dark.csv", record_uniform(truth, 60, lux=0.0))
    (tmp_path / "m.toml").write_text(f'[camera_dark]\nlines = "{name}"\n')
    result = calibrate(load_measurements(tmp_path / "m.toml"), CAR)
    cam = result.car_after.camera
    assert cam.black_level_dn == pytest.approx(12.0, abs=0.6)
    assert cam.dsnu_e == pytest.approx(120000.0, rel=0.25)
    assert cam.dark_noise_e == pytest.approx(50000.0, rel=0.15)
    # as many per row over the sensor as the recording's line row shows (its seeded places)
    assert cam.hot_pixels == _expected_defects(truth, "hot_pixels") * 128 > 0
    assert "[camera_dark] EMVA 1288 (dark measurements)" in result.report()


def test_flat_field_gives_the_fall_off_and_each_pixels_response(tmp_path):
    truth = camera(vignetting_power=6.0, prnu=0.05, dead_pixels=640, exposure_s=0.01)
    name = save(tmp_path / "flat.csv", record_uniform(truth, 40, lux=500.0, exposure_s=0.01))
    (tmp_path / "m.toml").write_text(f'[camera_flat]\nlines = "{name}"\n')
    cam = calibrate(load_measurements(tmp_path / "m.toml"), CAR).car_after.camera
    assert cam.vignetting_power == pytest.approx(6.0, abs=0.3)
    assert cam.prnu == 0.0 and len(cam.vignetting_profile) == 128
    # the measured response carries the camera's own gain pattern in its line row
    g = 1 + 0.05 * np.random.default_rng(truth.camera.fixed_pattern_seed).standard_normal((128, 128))[60]
    prof = np.array(cam.vignetting_profile)
    live = prof > 0.5
    assert np.corrcoef(prof[live], g[live])[0, 1] > 0.9
    assert cam.dead_pixels == _expected_defects(truth, "dead_pixels") * 128 > 0


def test_exposure_sweep_measures_the_photon_transfer_when_the_noise_shows(tmp_path):
    truth = camera(saturation_capacity_e=20000.0, dark_noise_e=50.0)  # 0.0128 counts per electron
    exposures = [0.00001, 0.00002, 0.00003, 0.00004, 0.00005]  # 30 .. 170 counts, unclipped
    names = [save(tmp_path / f"e{i}.csv", record_uniform(truth, 80, lux=500.0, exposure_s=t, seed=i))
             for i, t in enumerate(exposures)]
    (tmp_path / "m.toml").write_text(f"[camera_sweep]\nexposures_s = {exposures}\nlines = {names}\n")
    res = calibrate(load_measurements(tmp_path / "m.toml"), CAR)
    assert res.car_after.camera.saturation_capacity_e == pytest.approx(20000.0, rel=0.2)
    quiet = [save(tmp_path / f"q{i}.csv", record_uniform(CAR, 20, lux=500.0, exposure_s=t, seed=i))
             for i, t in enumerate([0.002, 0.005, 0.01])]
    (tmp_path / "q.toml").write_text(f"[camera_sweep]\nexposures_s = [0.002, 0.005, 0.01]\nlines = {quiet}\n")
    res = calibrate(load_measurements(tmp_path / "q.toml"), CAR)
    assert res.car_after.camera.saturation_capacity_e == CAR.camera.saturation_capacity_e
    assert "below what 8-bit lines show" in res.report()


@pytest.mark.parametrize("body, message", [
    ('[camera_flat]\nlines = "missing.csv"\n', "camera_flat.lines: "),
    ('[camera_flat]\nlines = 3\n', ":2: camera_flat.lines: expected a file name"),
    ("[camera_sweep]\nexposures_s = [0.01, 0.02]\nlines = [\"a.csv\"]\n", "1 files for 2 exposures"),
])
def test_bad_camera_sections_are_one_line(tmp_path, body, message):
    (tmp_path / "a.csv").write_text("\n".join(",".join(["200"] * 63 + ["150"] * 65) for _ in range(3)))
    (tmp_path / "m.toml").write_text(body)
    res = CliRunner().invoke(cli, ["calibrate", str(tmp_path / "m.toml"), "-o", str(tmp_path / "new.toml")])
    assert res.exit_code == 2 and message in res.output and len(res.output.strip().splitlines()) == 1
    assert not (tmp_path / "new.toml").exists()
