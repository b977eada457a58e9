"""Camera: ground-plane projection of the top-down raster (simrunner.sensors.camera)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from pieces.pose import Pose2
from simrunner.errors import CameraError
from simrunner.sensors.camera import Camera
from simrunner.track.raster import BLACK_GRAY, WHITE_GRAY, build_raster, layer_from_polygon
from vehicle.description import Camera as CameraSpec

TRACKS = Path(__file__).resolve().parents[2] / "shared" / "tracks"
LANE_HALF_M = 0.255  # white half width; edge lines 0.02 m outside it: 0.55 m edge to edge
LINE_M = 0.02
FINISH_X_M = 1.0  # centre of a 0.05 m finish bar across the lane
FINISH_W_M = 0.05
# A camera that sees the whole lane at row 60 (the lead may adopt these as car.toml defaults).
WIDE = CameraSpec(hfov_rad=1.40, pitch_rad=0.57)


def straight_raster(finish: bool = False):
    box = shapely.box
    lane = box(-1.0, -LANE_HALF_M, 4.0, LANE_HALF_M)
    edges = box(-1.0, LANE_HALF_M, 4.0, LANE_HALF_M + LINE_M).union(
        box(-1.0, -LANE_HALF_M - LINE_M, 4.0, -LANE_HALF_M))
    layers = [layer_from_polygon("lane", lane, WHITE_GRAY), layer_from_polygon("edges", edges, BLACK_GRAY)]
    if finish:
        bar = box(FINISH_X_M - FINISH_W_M / 2, -LANE_HALF_M, FINISH_X_M + FINISH_W_M / 2, LANE_HALF_M)
        layers.append(layer_from_polygon("finish", bar, BLACK_GRAY))
    return build_raster(layers)


@pytest.fixture(scope="module")
def lane():
    return straight_raster()


def white_span(row: np.ndarray) -> tuple[int, int]:
    white = np.flatnonzero(row > 128)
    assert len(white), "no white lane in the row"
    return int(white[0]), int(white[-1])


def test_centred_lane_is_symmetric_and_both_edge_lines_seen(lane):
    cam = Camera(WIDE, lane)
    row = cam.render_row(Pose2(), 60)
    left, right = white_span(row)
    assert abs((left + right) / 2 - (cam.width_px - 1) / 2) <= 1.0
    # Black edge lines (darker than the floor) just outside the white, floor beyond them.
    assert row[:left].min() < 30 and row[right + 1:].min() < 30
    assert row[0] == lane.floor_gray and row[-1] == lane.floor_gray
    full = cam.render(Pose2())
    for r in (40, 60, 80):
        lo, hi = white_span(full[r])
        assert abs((lo + hi) / 2 - (cam.width_px - 1) / 2) <= 1.0


def test_car_left_of_centre_sees_lane_shifted_right(lane):
    cam = Camera(WIDE, lane)
    c0 = np.mean(white_span(cam.render_row(Pose2(), 60)))
    c1 = np.mean(white_span(cam.render_row(Pose2(0.0, 0.1, 0.0), 60)))
    px_per_m = cam.width_px / cam.visible_width_m(60)
    assert c1 - c0 == pytest.approx(0.1 * px_per_m, abs=1.5)
    # and turning left (yaw > 0) also moves the lane to the right of the image
    c2 = np.mean(white_span(cam.render_row(Pose2(0.0, 0.0, 0.1), 60)))
    assert c2 > c0 + 5


def test_column_zero_is_left_and_row_zero_is_far():
    cam = Camera(CameraSpec(), straight_raster())
    # the first rows of the default camera may look above the horizon (no ground: NaN)
    top = next(r for r in range(cam.height_px) if math.isfinite(cam.ground_point_of_pixel(r, 0)[1]))
    assert top < 60
    x0, y0 = cam.ground_point_of_pixel(top, 0)
    x1, y1 = cam.ground_point_of_pixel(cam.height_px - 1, cam.width_px - 1)
    assert y0 > 0 > y1
    assert x0 > x1 > CameraSpec().forward_m
    assert cam.look_ahead_m(top) > cam.look_ahead_m(60) > cam.look_ahead_m(cam.height_px - 1)
    # look_ahead_m is the pixel geometry: tan(depression) = height / distance
    spec = CameraSpec()
    f = (spec.width_px / 2) / math.tan(spec.hfov_rad / 2)
    dep = spec.pitch_rad + math.atan((60.5 - spec.height_px / 2) / f)
    assert cam.look_ahead_m(60) == pytest.approx(spec.forward_m + spec.height_m / math.tan(dep), rel=1e-12)


def test_finish_marking_seen_only_in_rows_that_look_at_it():
    """The thesis's row test (Fig. 5.2-5.4): which rows see a finish bar ahead of the car."""
    raster = straight_raster(finish=True)
    cam = Camera(WIDE, raster)
    pose = Pose2(0.2, 0.0, 0.0)
    img = cam.render(pose)
    mid = img[:, cam.width_px // 2 - 2: cam.width_px // 2 + 2].astype(float).mean(axis=1)
    on_lane = np.array([pose.x_m + cam.look_ahead_m(r) < 3.5 for r in range(cam.height_px)])
    seen = (mid < 128) & on_lane  # rows beyond the lane's end see the floor
    assert on_lane.sum() > 100
    assert 0 < seen.sum() < 10
    for r in range(cam.height_px):
        ahead = pose.x_m + cam.look_ahead_m(r) - FINISH_X_M  # ground under row r vs bar centre
        if abs(ahead) < FINISH_W_M / 2 - 0.01:
            assert seen[r], r
        elif abs(ahead) > FINISH_W_M / 2 + 0.01:
            assert not seen[r], r
    # The row test of Fig. 5.2: moving the car changes which rows see the bar.
    rows_near = set(np.flatnonzero(seen))
    img2 = cam.render(Pose2(0.0, 0.0, 0.0))
    rows_far = set(np.flatnonzero((img2[:, 62:66].astype(float).mean(axis=1) < 128) & on_lane))
    assert rows_far and min(rows_far) < min(rows_near)


@pytest.mark.parametrize("supersample", [1, 2, 3])
def test_render_row_equals_render_and_is_deterministic(lane, supersample):
    cam = Camera(WIDE, lane, supersample=supersample)
    rng = np.random.default_rng(3)
    for _ in range(5):
        pose = Pose2(rng.uniform(-0.5, 2), rng.uniform(-0.2, 0.2), rng.uniform(-0.5, 0.5))
        img = cam.render(pose)
        assert img.shape == (cam.height_px, cam.width_px) and img.dtype == np.uint8
        assert np.array_equal(img, cam.render(pose))
        for r in (0, 17, 60, cam.height_px - 1):
            assert np.array_equal(cam.render_row(pose, r), img[r])
    with pytest.raises(CameraError, match="row 128"):
        cam.render_row(Pose2(), 128)


def test_noise_std_and_determinism(lane):
    spec = CameraSpec(noise_std=6.0)
    cam = Camera(spec, lane)
    img = np.full((128, 128), 128, dtype=np.uint8)
    a = cam.add_noise(img, np.random.default_rng(42))
    b = cam.add_noise(img, np.random.default_rng(42))
    c = cam.add_noise(img, np.random.default_rng(43))
    assert a.dtype == np.uint8 and a.shape == img.shape
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert np.all(img == 128)  # input untouched
    # rounding adds 1/12 to the variance; 16384 samples give ~0.6 % std error
    assert (a.astype(float) - 128).std() == pytest.approx(math.sqrt(6.0 ** 2 + 1 / 12), rel=0.03)
    assert abs((a.astype(float) - 128).mean()) < 0.2
    sat = cam.add_noise(np.full((64, 64), 250, np.uint8), np.random.default_rng(0))
    assert sat.max() == 255


def test_rays_above_horizon_see_floor(lane):
    cam = Camera(CameraSpec(pitch_rad=0.2), lane)
    img = cam.render(Pose2())
    assert math.isinf(cam.look_ahead_m(0))
    assert np.all(img[0] == lane.floor_gray)


def nxp_raster():
    from simrunner.track.load import load_track

    folder = TRACKS / "nxp_raceway"
    if not folder.is_dir():
        pytest.skip(f"NXP tracks not found at {TRACKS} (expected beside the checkout)")
    return load_track(folder).raster


def test_nxp_raceway_start_view_is_white_lane_between_black_borders():
    raster = nxp_raster()
    cam = Camera(WIDE, raster)
    row = cam.render_row(Pose2(), 60)
    left, right = white_span(row)
    assert row[60:68].min() > 200
    assert row[:left].min() < 30 and row[right + 1:].min() < 30
    assert abs((left + right) / 2 - 63.5) <= 2.0  # NXP's start is on the lane centre


@settings(max_examples=60, deadline=None)
@given(pitch=st.floats(0.2, 1.3), height=st.floats(0.05, 0.6), hfov=st.floats(0.3, 2.4),
       row=st.integers(0, 127), col=st.integers(0, 127))
def test_ground_point_reprojects_to_its_pixel(lane, pitch, height, hfov, row, col):
    """Pinhole round trip: the ground point of a pixel projects back onto that pixel's centre."""
    spec = CameraSpec(pitch_rad=pitch, height_m=height, hfov_rad=hfov)
    cam = Camera(spec, lane, max_range_m=1e6)
    gx, gy = cam.ground_point_of_pixel(row, col)
    if math.isnan(gx):
        # only rays at or above the horizon miss the ground
        f = (spec.width_px / 2) / math.tan(hfov / 2)
        assert math.atan((row + 0.5 - spec.height_px / 2) / f) + pitch <= 1e-9
        return
    d = np.array([gx - spec.forward_m, gy, -height])
    fwd = np.array([math.cos(pitch), 0.0, -math.sin(pitch)])
    up = np.array([math.sin(pitch), 0.0, math.cos(pitch)])
    f_px = (spec.width_px / 2) / math.tan(hfov / 2)
    u = -f_px * d[1] / (d @ fwd)
    v = -f_px * (d @ up) / (d @ fwd)
    assert u + spec.width_px / 2 - 0.5 == pytest.approx(col, abs=1e-6)
    assert v + spec.height_px / 2 - 0.5 == pytest.approx(row, abs=1e-6)


@settings(max_examples=40, deadline=None)
@given(x=st.floats(-1, 3), y=st.floats(-0.2, 0.2), yaw=st.floats(-3.1, 3.1))
def test_pixel_shows_the_raster_at_its_ground_point(lane, x, y, yaw):
    """A rendered pixel equals the raster's bilinear value at the pixel's world ground point."""
    cam = Camera(WIDE, lane)
    pose = Pose2(x, y, yaw)
    img = cam.render(pose)
    for row, col in ((60, 10), (60, 64), (100, 120), (127, 0)):
        world = pose.apply(np.array([cam.ground_point_of_pixel(row, col)]))
        px = lane.world_to_px(world)[0]
        c0, r0 = int(math.floor(px[0])), int(math.floor(px[1]))
        h, w = lane.shape
        if not (0 <= c0 < w - 1 and 0 <= r0 < h - 1):
            if not (-1 <= c0 < w and -1 <= r0 < h):
                assert img[row, col] == lane.floor_gray  # off the raster: the floor
            continue
        fc, fr = px[0] - c0, px[1] - r0
        patch = lane.image[r0:r0 + 2, c0:c0 + 2].astype(float)
        want = (patch[0, 0] * (1 - fc) * (1 - fr) + patch[0, 1] * fc * (1 - fr)
                + patch[1, 0] * (1 - fc) * fr + patch[1, 1] * fc * fr)
        # float32 map coordinates (~1e-4 px) and float32 arithmetic, then rounding to a whole gray
        assert abs(int(img[row, col]) - want) <= 0.55


@settings(max_examples=50, deadline=None)
@given(x=st.floats(-5, 5), y=st.floats(-5, 5))
def test_raster_pixel_world_round_trip(lane, x, y):
    px = lane.world_to_px([[x, y]])
    assert np.allclose(lane.px_to_world(px), [[x, y]], atol=1e-9)
    # +x goes right (col up), +y goes up the image (row down)
    step = lane.world_to_px([[x + 1.0, y + 1.0]]) - px
    assert np.allclose(step, [[1.0 / lane.m_per_px, -1.0 / lane.m_per_px]])
