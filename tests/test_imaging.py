"""The physical camera (camera.model linescan / area, simrunner.sensors.imaging): each stage of
the light -> electrons -> counts chain measured on scenes whose answer is known, the exposure
API on the lockstep clock, and the car file's camera fields."""
from __future__ import annotations

import dataclasses
import math
import textwrap

import numpy as np
import pytest
import shapely

from pieces.pose import Pose2
from simrunner import CommandError, Spinner
from simrunner.run.clock import LockstepClock
from simrunner.run.spinner import Session
from simrunner.sensors.camera import Camera
from simrunner.sensors.imaging import PHOTONS_PER_LM_S, Imager, bilinear_f64, blur_rows, pad_with_floor
from simrunner.track.raster import BLACK_GRAY, WHITE_GRAY, build_raster, layer_from_polygon
from vehicle.description import CarDescription, CarDescriptionError, load_car
from worlds.lighting import TrackLighting

CAR = CarDescription()
QUIET = dict(prnu=0.0, dsnu_e=0.0, dark_current_eps=0.0, psf_sigma_px=0.0, motion_blur_samples=1,
             startup_frames=0, black_level_dn=0.0)


def spec(**kw):
    return dataclasses.replace(CAR.camera, model=kw.pop("model", "linescan"), **kw)


@pytest.fixture(scope="module")
def white():
    """A white floor 20 m wide around the origin: every ray sees the lane's reflectance."""
    return build_raster([layer_from_polygon("lane", shapely.box(-10, -10, 10, 10), WHITE_GRAY)])


@pytest.fixture(scope="module")
def stripe():
    """White with one 2 cm black line along x at y = 0 (the car looks along x)."""
    return build_raster([layer_from_polygon("lane", shapely.box(-10, -10, 10, 10), WHITE_GRAY),
                         layer_from_polygon("edge", shapely.box(-10, -0.01, 10, 0.01), BLACK_GRAY, top_z_m=0.001)])


def imager(raster, lux=500.0, **kw):
    return Imager(Camera(spec(**kw), raster), TrackLighting(ambient_lux=lux))


def line(im, exposure_s, row=60, **kw):
    return im.line(Pose2(), row, exposure_s=exposure_s, **kw)[0].astype(float)


def test_signal_is_light_times_exposure_by_the_emva_chain(white):
    im = imager(white, **QUIET, vignetting_power=0.0)
    c = im.spec
    # centre pixel: rho E tau / (4 N^2) x eta A k x t electrons, K counts each
    rho = WHITE_GRAY / 255.0
    e = rho * 500.0 * c.lens_transmission / (4 * c.f_number ** 2) * c.quantum_efficiency \
        * c.pixel_area_um2 * 1e-12 * PHOTONS_PER_LM_S * 0.004
    want = e * 255.0 / c.saturation_capacity_e
    assert line(im, 0.004)[64] == pytest.approx(want, abs=0.5)
    # linear in exposure and in light below saturation
    assert line(im, 0.008)[64] == pytest.approx(2 * want, abs=0.5)
    assert line(imager(white, lux=250.0, **QUIET, vignetting_power=0.0), 0.008)[64] == pytest.approx(want, abs=0.5)


def test_saturation_clips_at_the_adc_maximum(white):
    im = imager(white, **QUIET)
    long = line(im, 0.2)
    assert long.max() == 255 and np.mean(long == 255) > 0.9
    assert line(im, 0.001).max() < 60


def test_vignetting_follows_cos_power_and_the_measured_profile(white):
    im = imager(white, **QUIET)
    centre = im.gain_e_per_lux_s[60, 64]
    w, f = 128, im.camera.f_px
    for col in (0, 20, 127):
        u, v = col + 0.5 - 64, 60.5 - 64
        cos = f / math.sqrt(f * f + u * u + v * v)
        cos0 = f / math.sqrt(f * f + 0.25 + v * v)
        assert im.gain_e_per_lux_s[60, col] / centre == pytest.approx((cos / cos0) ** 4, rel=1e-9)
    flat = line(im, 0.01)
    assert flat[0] < 0.5 * flat[64]  # the strong fall-off of a 75 degree lens at its ends
    profile = tuple(np.linspace(0.5, 1.0, w))
    pim = imager(white, **QUIET, vignetting_profile=profile)
    assert pim.gain_e_per_lux_s[60, 0] / im.gain_e_per_lux_s[60, 0] == pytest.approx(0.5)


def test_optical_blur_keeps_a_thin_line_from_reaching_black(stripe):
    sharp = line(imager(stripe, **{**QUIET, "vignetting_power": 0.0}), 0.01)
    blurred = line(imager(stripe, **{**QUIET, "vignetting_power": 0.0, "psf_sigma_px": 1.5}), 0.01)
    lane = np.median(sharp)
    assert sharp.min() < 0.35 * lane  # the 2 cm line spans a few pixels: it reaches dark
    assert blurred.min() > sharp.min() + 0.15 * lane
    assert abs(blurred.sum() - sharp.sum()) < 0.02 * sharp.sum()  # blur moves light, keeps it


def test_motion_blur_smears_the_line_across_the_row(stripe):
    im = imager(stripe, **{**QUIET, "vignetting_power": 0.0, "motion_blur_samples": 8})
    still = line(im, 0.02, twist=(0.0, 0.0, 0.0))
    moving = line(im, 0.02, twist=(0.0, 3.0, 0.0))  # sliding sideways at 3 m/s: 6 cm in 20 ms
    lane = np.median(still)
    dark_still = np.count_nonzero(still < 0.9 * lane)
    dark_moving = np.count_nonzero(moving < 0.9 * lane)
    assert dark_moving > dark_still + 2 and moving.min() > still.min()
    assert line(im, 0.02, twist=None).tolist() == still.tolist()


def test_temporal_noise_is_shot_plus_dark_and_off_without_add_noise(white):
    im = imager(white, **{**QUIET, "vignetting_power": 0.0, "adc_bits": 16})
    rng = np.random.default_rng(1)
    frames = np.array([im.line(Pose2(), 60, exposure_s=0.004, normals=rng)[0] for _ in range(2)])
    assert frames.dtype == np.uint8
    # 16-bit counts are delivered as their top 8 bits; measure in electrons through 16 bits
    im16 = imager(white, **{**QUIET, "vignetting_power": 0.0, "adc_bits": 16})
    e = im16.gain_e_per_lux_s[60, 64] * (WHITE_GRAY / 255.0 * 500.0) * 0.004
    rng = np.random.default_rng(2)
    z = rng.standard_normal((400, 2, 128))
    sigma_e = np.std(np.sqrt(e) * z[:, 0] + im16.spec.dark_noise_e * z[:, 1])
    assert sigma_e == pytest.approx(math.sqrt(e + im16.spec.dark_noise_e ** 2), rel=0.05)
    clean = [im.line(Pose2(), 60, exposure_s=0.004, normals=None)[0] for _ in range(3)]
    assert all(np.array_equal(c, clean[0]) for c in clean)


def test_noise_in_counts_matches_the_model(white):
    im = imager(white, **{**QUIET, "vignetting_power": 0.0, "dark_noise_e": 20000.0})
    rng = np.random.default_rng(3)
    rows = np.array([line(im, 0.004, normals=rng)[40:88] for _ in range(200)])
    e = im.gain_e_per_lux_s[60, 64] * (WHITE_GRAY / 255.0 * 500.0) * 0.004
    want = math.sqrt(e + 20000.0 ** 2) * 255.0 / im.full_e
    assert rows.std(axis=0).mean() == pytest.approx(math.sqrt(want ** 2 + 1 / 12), rel=0.1)


def test_fixed_pattern_is_the_cameras_own(white):
    kw = {**QUIET, "prnu": 0.05, "dsnu_e": 1e5, "vignetting_power": 0.0}
    a, b = imager(white, **kw), imager(white, **kw)
    c = imager(white, **kw, fixed_pattern_seed=2)
    assert np.array_equal(line(a, 0.01), line(b, 0.01))
    assert not np.array_equal(line(a, 0.01), line(c, 0.01))
    dark = line(imager(white, lux=0.0, **{**kw, "black_level_dn": 20.0}), 0.01)
    assert dark.std() == pytest.approx(1e5 * 255 / a.full_e, rel=0.25)
    assert dark.mean() == pytest.approx(20.0, abs=1.0)


def test_dead_and_hot_pixels(white):
    im = imager(white, **{**QUIET, "black_level_dn": 6.0}, dead_pixels=200, hot_pixels=300)
    img = im.frame(Pose2(), exposure_s=0.005)
    assert np.count_nonzero(im.dead) == 200 and np.count_nonzero(im.hot) == 300
    assert (img[im.dead] == 6).all() and (img[im.hot] == 255).all()
    assert not (im.dead & im.hot).any()


def test_adc_bits_and_gain(white):
    four = line(imager(white, **QUIET, adc_bits=4), 0.01)
    assert (four % 16 == 0).all() and len(set(four)) >= 2  # 4-bit counts shifted up to the top bits
    assert line(imager(white, **QUIET, adc_bits=4), 1.0).max() == 240  # 15 << 4
    twelve = imager(white, **QUIET, adc_bits=12)
    eight = imager(white, **QUIET)
    assert np.abs(line(twelve, 0.01) - line(eight, 0.01)).max() <= 1
    assert line(imager(white, **QUIET, analog_gain=2.0), 0.005)[64] == pytest.approx(
        2 * line(eight, 0.005)[64], abs=1.0)


def test_startup_frames_read_full(white):
    im = imager(white, **{**QUIET, "startup_frames": 2})
    assert (line(im, 0.001, frame_index=1) == 255).all()
    assert (line(im, 0.001, frame_index=2) == 255).all()
    assert line(im, 0.001, frame_index=3).max() < 60


def test_bilinear_f64_inside_and_at_the_border():
    img = np.array([[0, 100], [50, 150]], np.uint8)
    assert bilinear_f64(img, np.array([0.5]), np.array([0.5]), 7.0)[0] == pytest.approx(75.0)
    assert bilinear_f64(img, np.array([0.25]), np.array([0.0]), 7.0)[0] == pytest.approx(25.0)
    assert bilinear_f64(img, np.array([-0.5]), np.array([0.0]), 8.0)[0] == pytest.approx(4.0)
    assert bilinear_f64(img, np.array([5.0]), np.array([5.0]), 8.0)[0] == 8.0


@pytest.mark.parametrize("dtype, floor", [(np.uint8, 40.0), (np.uint8, 40.3), (np.uint16, 9000.0),
                                          (np.uint16, 70000.0)])
def test_bilinear_f64_reads_the_padded_image_as_the_masked_one_bit_for_bit(dtype, floor):
    rng = np.random.default_rng(3)
    img = rng.integers(0, np.iinfo(dtype).max, (30, 41)).astype(dtype)
    padded = pad_with_floor(img, floor)
    assert padded.dtype == (dtype if floor == int(floor) and floor <= np.iinfo(dtype).max else np.float64)
    sx, sy = rng.uniform(-6, 47, (2, 50, 60))  # inside, across every border, far outside
    sx[0, :4], sy[1, :3] = (np.nan, np.inf, -np.inf, 1e300), (np.nan, -1e300, np.inf)
    with np.errstate(invalid="ignore"):  # inf - inf, a NaN cast to an index (read as outside)
        slow = bilinear_f64(img, sx, sy, floor)
        fast = bilinear_f64(img, sx, sy, floor, padded=padded)
    assert np.array_equal(slow, fast, equal_nan=True)
    assert np.isnan(fast[0, 0]) and fast[0, 3] == floor  # no ray; far off the image: the floor


@pytest.mark.parametrize("taps", [1, 3, 7, 13])
def test_blur_rows_is_np_convolve_row_by_row_bit_for_bit(taps):
    rng = np.random.default_rng(taps)
    kernel = rng.uniform(0, 1, taps)
    for shape in ((1, 134), (128, 134), (5, taps), (3, 200)):
        scene = rng.uniform(0, 5000, shape) * rng.choice([1e-3, 1.0, 1e3], shape)
        rows = np.stack([np.convolve(r, kernel, mode="valid") for r in scene])
        got = blur_rows(scene, kernel)
        assert got.shape == rows.shape and np.array_equal(got, rows)
        assert np.array_equal(blur_rows(scene[:, ::-1], kernel), np.stack([np.convolve(r, kernel, mode="valid")
                                                                           for r in scene[:, ::-1]]))


# -- exposure on the lockstep clock --------------------------------------------------------
class StillSim:
    steps = 0
    speed_mps = lateral_speed_mps = yaw_rate_radps = 0.0

    def set_command(self, *a):
        pass

    def step(self, n=1):
        self.steps += n

    @property
    def pose(self):
        return Pose2()


def spinner(raster, model="linescan", **kw):
    car = CAR.replace(camera=spec(model=model, **kw))
    cam = Camera(car.camera, raster)
    clock = LockstepClock(StillSim(), dt_s=0.001, frame_period_s=car.camera.frame_period_s())
    imager_ = Imager(cam) if model != "ideal" else None
    session = Session(clock=clock, camera=cam, car=car, rng=np.random.default_rng(0), imager=imager_)
    return Spinner(session=session), clock


def frame_times(s, n=4):
    out = []
    for _ in range(n):
        s.get_image(60)
        out.append(round(s._clock.time_s, 9))
    return np.diff(out)


def test_linescan_frames_are_exposure_plus_readout_apart(white):
    s, clock = spinner(white, exposure_s=0.0095, readout_s=0.0005)
    assert s.get_exposure() == 0.0095 and s.getExposure() == 0.0095
    assert frame_times(s) == pytest.approx([0.010] * 3)
    s.set_exposure(0.0045)
    assert s.get_exposure() == 0.0045
    assert frame_times(s) == pytest.approx([0.005] * 3)
    bright = s.get_image(60, add_noise=False)[0]
    s.setExposure(0.0015)
    dim = s.get_image(60, add_noise=False)[0]
    assert dim[64] < 0.5 * bright[64]


def test_set_exposure_applies_to_the_frame_in_progress(white):
    s, clock = spinner(white, exposure_s=0.0195, readout_s=0.0005)
    s.get_image(60)            # frame 1 at 20 ms
    s.sleep(0.003)             # 23 ms: frame 2 would end at 40 ms
    s.set_exposure(0.0045)     # ... now at 20 + 5 = 25 ms
    s.get_image(60)
    assert clock.time_s == pytest.approx(0.025)
    s.sleep(0.008)             # 33 ms: a frame ended at 30 ms, the one in progress began there
    s.set_exposure(0.0095)     # ... so it ends at 30 + 10 = 40 ms
    s.get_image(60)
    assert clock.time_s == pytest.approx(0.040)
    s.sleep(0.004)             # 44 ms, past 40 + 2: a new period starts now
    s.set_exposure(0.0015)
    s.get_image(60)
    assert clock.time_s == pytest.approx(0.046)


def test_set_exposure_next_frame_loads_at_the_end_of_the_frame_in_progress(white):
    """set_exposure(next_frame=True), a kit's period register written while the timer runs: the
    frame in progress keeps its period and its exposure - get_image gives it as bright as the one
    before - the next one is integrated over the new exposure and lasts it; of several values the
    last loads, and get_exposure gives the one in force. A plain set_exposure drops one waiting."""
    s, clock = spinner(white, exposure_s=0.005, readout_s=0.0005)
    s.camera_free_running()        # frames one exposure apart (a kit's)
    s.get_image(60)
    before = s.get_image(60, add_noise=False)[0]
    t0 = clock.time_s
    s.sleep(0.002)
    s.set_exposure(0.002, next_frame=True)
    s.set_exposure(0.010, next_frame=True)  # (the last one loads)
    assert s.get_exposure() == 0.005
    same = s.get_image(60, add_noise=False)[0]  # the frame in progress: 5 ms, its own exposure
    assert clock.time_s == pytest.approx(t0 + 0.005) and s.get_exposure() == 0.010
    assert np.array_equal(same, before)
    brighter = s.get_image(60, add_noise=False)[0]
    assert clock.time_s == pytest.approx(t0 + 0.005 + 0.010)
    assert brighter[64] > 1.5 * same[64]
    s.set_exposure(0.002, next_frame=True)
    s.set_exposure(0.005)          # at once, and the waiting one is dropped
    assert frame_times(s) == pytest.approx([0.005] * 3)
    with pytest.raises(CommandError, match=r"set_exposure\(seconds=2.0\): expected 1e-05 to 1 s"):
        s.set_exposure(2.0, next_frame=True)


def test_area_and_ideal_cameras_keep_their_frame_rate(white):
    s, _ = spinner(white, model="area", exposure_s=0.01)
    s.set_exposure(0.002)
    assert frame_times(s) == pytest.approx([0.02] * 3)
    with pytest.raises(CommandError, match=r"set_exposure\(seconds=0.03\): expected 1e-05 to 0.02 s"):
        s.set_exposure(0.03)
    s, _ = spinner(white, model="ideal")
    before = s.get_image(60)
    s.set_exposure(0.001)
    assert s.get_exposure() == 0.001 and frame_times(s) == pytest.approx([0.02] * 3)
    assert before.dtype == np.uint8


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), 2.0, "fast"])
def test_bad_exposures_are_one_line_errors(white, bad):
    s, _ = spinner(white)
    with pytest.raises(CommandError, match=r"set_exposure\(seconds="):
        s.set_exposure(bad)


def test_same_seed_same_bytes_with_every_effect_on(tmp_path, white):
    from simrunner.run.runner import drive

    toml = tmp_path / "car.toml"
    CAR.replace(camera=spec(dead_pixels=3, hot_pixels=2, startup_frames=2, prnu=0.05,
                            psf_sigma_px=1.0, motion_blur_samples=4)).save(toml)
    ctrl = tmp_path / "c.py"
    ctrl.write_text(textwrap.dedent("""\
        import zlib
        def main(s):
            s.set_speed_and_servo(1.5, 0.0)
            while s.get_time() < 1.0:
                row = s.get_image(s.line_row)
                s.add_data([f"{zlib.crc32(row.tobytes()):08x} {int(row.min())} {int(row.max())}"])
        """))
    digests = []
    for name, seed in (("a", 3), ("b", 3), ("c", 4)):
        drive(ctrl, car=toml, seed=seed, csv=tmp_path / f"{name}.csv", time_limit_s=1.2)
        digests.append((tmp_path / f"{name}.csv").read_bytes())
    assert digests[0] == digests[1] and digests[0] != digests[2]
    text = digests[0].decode()
    assert " 255 255" in text  # the start-up frames


# -- the car file ---------------------------------------------------------------------------
@pytest.mark.parametrize("body, message", [
    ('model = "fisheye"', "camera.model = 'fisheye': expected one of 'ideal', 'linescan', 'area'"),
    ("vignetting_profile = [1.0, 0.9]", "camera.vignetting_profile has 2 numbers: expected one per column"),
    ('vignetting_profile = "flat"', "camera.vignetting_profile = 'flat': expected a list of numbers"),
    ("vignetting_profile = [1.0, -1.0]", "camera.vignetting_profile[1] = -1.0: expected a number in [0.0, 10.0]"),
    ('model = "area"\nexposure_s = 0.05', "camera.exposure_s = 0.05: an area camera exposes within its frame"),
    ("adc_bits = 20", "camera.adc_bits = 20: expected a value in [1, 16]"),
])
def test_camera_fields_are_checked_with_their_line(tmp_path, body, message):
    path = tmp_path / "car.toml"
    path.write_text(f"[camera]\n{body}\n")
    with pytest.raises(CarDescriptionError) as err:
        load_car(path)
    assert str(err.value).startswith(f"{path}:")
    assert message in str(err.value)


def test_camera_file_round_trip_and_the_default_line_camera(tmp_path):
    assert CAR.camera.model == "linescan" and CAR.camera.frame_period_s() == pytest.approx(0.02)  # 50 Hz
    car = CAR.replace(camera=spec(vignetting_profile=tuple(np.linspace(0.6, 1.0, 128))))
    car.save(tmp_path / "c.toml")
    back = load_car(tmp_path / "c.toml")
    assert back == car and back.camera.frame_period_s() == pytest.approx(0.02)


def test_an_area_cameras_blur_reaches_across_rows_and_a_line_is_its_frames_row(white):
    kw = {**QUIET, "psf_sigma_px": 1.5, "vignetting_power": 0.0}
    half = build_raster([layer_from_polygon("lane", shapely.box(-10, -10, 10, 10), WHITE_GRAY),
                         layer_from_polygon("edge", shapely.box(0.8, -10, 10, 10), BLACK_GRAY, top_z_m=0.001)])
    area = imager(half, model="area", exposure_s=0.01, **kw)
    scan = imager(half, model="linescan", **kw)
    frame = area.frame(Pose2(), exposure_s=0.01).astype(float)
    cols = frame[:, 64]
    edge = int(np.argmax(np.abs(np.diff(cols))))  # the far black area ends at one row
    assert 0 < cols[edge - 3] < cols[edge + 3] or cols[edge - 3] > cols[edge + 3] > 0
    for r in (edge - 1, edge, edge + 1, 0, 127):
        assert np.array_equal(area.line(Pose2(), r, exposure_s=0.01)[0], frame[r].astype(np.uint8))
    scan_frame = scan.frame(Pose2(), exposure_s=0.01, twist=(2.0, 0.5, 1.0), normals=np.random.default_rng(5))
    z = np.random.default_rng(5).standard_normal((2, 128, 128))  # the frame's normals, row 40's share
    class Row40:
        def standard_normal(self, shape):
            return z[:, 40:41, :].reshape(shape)
    assert np.array_equal(scan.line(Pose2(), 40, exposure_s=0.01, twist=(2.0, 0.5, 1.0), normals=Row40())[0],
                          scan_frame[40])
    # a line sensor has no rows to mix: its row is sharper across the boundary than the area row
    ramp_area = np.abs(np.diff(frame[edge - 3:edge + 4, 64])).max()
    ramp_scan = np.abs(np.diff([line(scan, 0.01, row=r)[64] for r in range(edge - 3, edge + 4)])).max()
    assert ramp_scan > ramp_area


@pytest.mark.parametrize("model", ["linescan", "area"])
@pytest.mark.parametrize("lit", [False, True])
def test_the_videos_preview_is_the_frame_within_one_count(model, lit):
    """Imager.preview (the debug video's camera view: OpenCV's fixed-point remap) differs from
    frame() without noise by at most 1 DN, on the default track's lines seen from poses along
    it, in the default hall and under lamps with other reflectances (a 16-bit reflectance image)."""
    from simrunner.run.runner import default_track
    from simrunner.track.load import load_track
    from worlds.lighting import Light

    track = load_track(default_track())
    lighting = (TrackLighting(ambient_lux=300.0, lights=(Light(1.0, 0.5, 2.0, 800.0), Light(2.5, -0.5, 1.5, 500.0, 60.0)),
                              lane_reflectance=0.8, line_reflectance=0.1, specular=0.3) if lit else None)
    im = Imager(Camera(spec(model=model), track), lighting)
    rng = np.random.default_rng(3)
    box = track.raster
    h, w = np.asarray(box.image).shape
    x0, y0 = (float(v) for v in box.origin_xy_m)
    diffs, changed = [], 0
    for _ in range(12):
        pose = Pose2(x0 + rng.uniform(0.2, 0.8) * w * box.m_per_px, y0 - rng.uniform(0.2, 0.8) * h * box.m_per_px,
                     rng.uniform(-math.pi, math.pi))
        exact = im.frame(pose, exposure_s=im.spec.exposure_s).astype(int)
        fast = im.preview(pose, exposure_s=im.spec.exposure_s).astype(int)
        diffs.append(np.abs(fast - exact).max())
        changed += int(np.ptp(exact) > 50)  # the view shows lines, not only one grey
    assert max(diffs) <= 1
    assert changed >= 3
