"""Light in the world (worlds.lighting): the photometry of lamps, layouts that set it, the world
files that carry it (ours and Gazebo's), and the line the physical camera sees under it."""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
import shutil
import subprocess

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from pieces.pose import Pose2
from simrunner.sensors.camera import Camera
from simrunner.sensors.imaging import Imager
from simrunner.track.load import load_track
from simrunner.track.raster import BLACK_GRAY, WHITE_GRAY, build_raster, layer_from_polygon
from trackgen import LayoutError
from trackgen.layout import parse_layout
from vehicle.description import CarDescription
from worlds.lighting import GAZEBO_LUX, SHADE_EDGE_M, Light, Shade, TrackLighting, from_json
from worlds.sdf_read import read_world

OVAL = "START_FINISH\nSTRAIGHT\nTURN_LEFT x4\nSTRAIGHT x2\nTURN_LEFT x4\n"


def test_a_lamp_follows_the_inverse_square_and_cosine_laws():
    lamp = Light(0.0, 0.0, 2.01, 800.0)
    assert lamp.illuminance_lux(0.0, 0.0, 0.01) == pytest.approx(800.0 / 4.0)
    # 2 m to the side at 2 m height: d = 2 sqrt(2), cos = 1 / sqrt(2)
    assert lamp.illuminance_lux(2.0, 0.0, 0.01) == pytest.approx(800.0 / 8.0 / math.sqrt(2.0))
    spot = Light(0.0, 0.0, 2.01, 800.0, cone_deg=60.0)  # half-angle 30 deg: 1.155 m at 2 m
    assert spot.illuminance_lux(0.5, 0.0, 0.01) == pytest.approx(lamp.illuminance_lux(0.5, 0.0, 0.01))
    assert spot.illuminance_lux(1.2, 0.0, 0.01) == 0.0
    assert 0.0 < spot.illuminance_lux(1.1, 0.0, 0.01) < lamp.illuminance_lux(1.1, 0.0, 0.01)
    assert Light(0, 0, 0.005, 100.0).illuminance_lux(0.0, 0.0, 0.01) == 0.0  # below the surface
    both = TrackLighting(ambient_lux=100.0, lights=(lamp, spot))
    assert both.illuminance_lux(np.array([0.0]), np.array([0.0]), 0.01)[0] == pytest.approx(500.0)
    assert TrackLighting().illuminance_lux(1.0, 2.0) == 500.0


@settings(max_examples=60, deadline=None)
@given(x=st.floats(-5, 5), y=st.floats(-5, 5), z=st.floats(0.2, 5), cd=st.floats(1, 5000))
def test_the_light_of_a_lamp_on_the_floor_adds_up_to_its_flux_into_the_lower_half(x, y, z, cd):
    """E integrates over the plane to 2 pi I lumens: an isotropic source sends 4 pi I, half of it down."""
    lamp = Light(x, y, z, cd)
    r = np.linspace(0.0, 400.0 * z, 400001)
    e = lamp.illuminance_lux(x + r, np.full_like(r, y), 0.0)
    flux = np.trapezoid(e * 2 * np.pi * r, r)
    assert flux == pytest.approx(2 * math.pi * cd, rel=0.01)


def test_layout_settings_make_the_lighting():
    layout = parse_layout("@ambient_lux = 80\n@light = 1 0 2 800 60\n@light = 3 0 2 400\n"
                          "@lane_reflectance = 0.85\n@specular = 0\n" + OVAL)
    lit = layout.lighting
    assert lit.ambient_lux == 80.0 and lit.lane_reflectance == 0.85 and lit.specular == 0.0
    assert lit.lights == (Light(1, 0, 2, 800, 60.0), Light(3, 0, 2, 400, None))
    scaled = parse_layout("@scale = 2\n@light = 1 0 2 800\n" + OVAL).lighting
    assert scaled.lights == (Light(2, 0, 4, 800, None),)
    assert parse_layout(OVAL).lighting.is_default()


def test_shades_in_a_layout_and_their_light():
    layout = parse_layout("@shade = 1 0 0.5 0.8 90 0.2\n@shade = 3 0 1 1 0 0\n" + OVAL)
    tunnel, shadow = layout.lighting.shades
    assert tunnel == Shade(1.0, 0.0, 0.5, 0.8, math.pi / 2, 0.2)
    assert parse_layout("@scale = 2\n@shade = 1 0 0.5 0.8 0 0.2\n" + OVAL).lighting.shades == (
        Shade(2.0, 0.0, 1.0, 1.6, 0.0, 0.2),)
    # along the heading (here +y) the roof is 0.5 m long, across it 0.8 m wide
    x = np.array([1.0, 1.0, 1.0, 1.3, 1.0, 1.0 + 0.4 - SHADE_EDGE_M / 2])
    y = np.array([0.0, 0.2, 0.3, 0.0, 0.25 - SHADE_EDGE_M / 2, 0.0])
    assert tunnel.factor(x, y) == pytest.approx([0.2, 0.2, 1.0, 0.2, 0.6, 0.6])
    lit = layout.lighting
    assert lit.illuminance_lux(np.array([1.0, 3.0, 5.0]), np.zeros(3)) == pytest.approx([100.0, 0.0, 500.0])
    assert from_json(json.loads(json.dumps(lit.to_json())), "t") == lit


@pytest.mark.parametrize("text, line, message", [
    ("@shade = 1 2 3\n", 1, "@shade = '1 2 3': expected '@shade = X Y LENGTH WIDTH HEADING_DEG TRANSMISSION'"),
    ("@shade = 1 2 0.5 0.5 0 1.5\n", 1, "@shade: TRANSMISSION = 1.5: expected 0 <= TRANSMISSION <= 1"),
    ("@shade = 1 2 0 0.5 0 0.5\n", 1, "@shade: LENGTH = 0: expected 0.01 <= LENGTH <= 1000"),
    ("@shade = 1 2 0.5 wide 0 0.5\n", 1, "@shade: WIDTH = 'wide': expected a number"),
    ("@light = 1 2\n", 1, "@light = '1 2': expected '@light = X Y Z INTENSITY_CD [CONE_DEG]'"),
    ("# lamps\n@light = 1 2 three 100\n", 2, "@light: Z = 'three': expected a number"),
    ("@light = 1 2 0.01 100\n", 1, "@light: Z = 0.01 m: expected 0.05 <= Z <= 100"),
    ("@light = 1 2 3 100 200\n", 1, "@light: CONE_DEG = 200: expected 1 <= CONE_DEG <= 179"),
    ("@light = 1 2 3 -5\n", 1, "@light: INTENSITY_CD = -5: expected 0 <= INTENSITY_CD <= 1e+07"),
    ("@ambient_lux = dark\n", 1, "@ambient_lux = 'dark': expected a number"),
    ("@ambient_lux = -1\n", 1, "@ambient_lux = -1: expected 0 <= ambient_lux <= 200000 (lux)"),
    ("@ambient_lux = 1\n@ambient_lux = 2\n", 2, "@ambient_lux set twice (first on line 1)"),
    ("@lane_reflectance = 1.5\n", 1, "@lane_reflectance = 1.5: expected 0 <= lane_reflectance <= 1"),
    ("@ambiant_lux = 4\n", 1, "unknown setting @ambiant_lux"),
])
def test_bad_light_settings_are_one_line_errors(text, line, message):
    with pytest.raises(LayoutError) as err:
        parse_layout(text + OVAL, path="lit.txt")
    assert str(err.value).startswith(f"lit.txt:{line}: ") and message in str(err.value)
    assert "\n" not in str(err.value)


def _build(tmp_path, text):
    from trackgen import load_layout
    from trackgen.build import build

    src = tmp_path / "lit.txt"
    src.write_text(text)
    out = tmp_path / "out"
    build(load_layout(src), out, force=True)
    return src, out


def test_build_writes_the_lamps_for_gazebo_and_reads_them_back(tmp_path):
    text = "@name = lit\n@ambient_lux = 60\n@light = 0.5 0 2.0 1500 70\n@light = 2.5 0.25 1.5 300\n" \
           "@floor_reflectance = 0.3\n@shade = 1.5 0 0.5 0.8 0 0.1\n" + OVAL
    src, out = _build(tmp_path, text)
    sdf = (out / "world.sdf").read_text()
    assert sdf.count("<light ") == 3 and 'type="spot"' in sdf and "<nxpcup:intensity_cd>1500<" in sdf
    assert json.loads((out / "track.json").read_text())["lighting"]["ambient_lux"] == 60.0
    want = parse_layout(text).lighting
    assert load_track(out).lighting == want  # the folder: world.sdf
    assert read_world(out / "world.sdf").lighting == want
    assert load_track(src).lighting == want  # the layout itself
    if shutil.which("ign"):
        check = subprocess.run(["ign", "sdf", "-k", str(out / "world.sdf")], capture_output=True, text=True)
        assert "Valid." in check.stdout, check.stdout + check.stderr


def test_a_layout_without_light_settings_builds_the_same_files(tmp_path):
    _, out = _build(tmp_path, "@name = plain\n" + OVAL)
    assert "<light " in (out / "world.sdf").read_text()  # the sun, for Gazebo, as before
    assert "nxpcup" not in (out / "world.sdf").read_text()
    assert "lighting" not in json.loads((out / "track.json").read_text())
    assert load_track(out).lighting.is_default()


def test_gazebo_lights_by_the_convention(tmp_path):
    (tmp_path / "w.sdf").write_text("""<?xml version="1.0"?>
<sdf version="1.6"><world name="w">
  <light name="sun" type="directional"><diffuse>0.8 0.8 0.8 1</diffuse><direction>0 0.6 -0.8</direction></light>
  <light name="up" type="directional"><diffuse>1 1 1 1</diffuse><direction>0 0 1</direction></light>
  <light name="bulb" type="point"><pose>1 2 3 0 0 0</pose><diffuse>0.5 0.5 0.5 1</diffuse></light>
  <light name="spot" type="spot"><pose>0 0 2 0 0 0</pose><spot><outer_angle>0.5</outer_angle></spot></light>
</world></sdf>""")
    lit = read_world(tmp_path / "w.sdf").lighting
    assert lit.ambient_lux == 500.0  # the sun is not read: the hall's ambient stands for it
    assert lit.lights[0] == Light(1.0, 2.0, 3.0, GAZEBO_LUX * 0.5, None)
    assert lit.lights[1].cone_deg == pytest.approx(math.degrees(1.0))
    (tmp_path / "sun.sdf").write_text('<sdf version="1.6"><world name="w"><light name="s" type="directional">'
                                      '<direction>0 0 -1</direction></light></world></sdf>')
    assert read_world(tmp_path / "sun.sdf").lighting is None  # the default hall


# -- what the physical camera sees ---------------------------------------------------------
@pytest.fixture(scope="module")
def floor():
    return build_raster([layer_from_polygon("lane", shapely.box(-10, -10, 10, 10), WHITE_GRAY),
                         layer_from_polygon("edge", shapely.box(-10, -0.01, 10, 0.01), BLACK_GRAY, top_z_m=0.001)])


def _line(raster, lighting, **cam):
    spec = dataclasses.replace(CarDescription().camera, model="linescan", prnu=0.0, dsnu_e=0.0,
                               psf_sigma_px=0.0, motion_blur_samples=1, startup_frames=0, **cam)
    im = Imager(Camera(spec, raster), lighting, surface_z_m=0.0)
    return im.line(Pose2(), 60, exposure_s=spec.exposure_s)[0].astype(float)


def test_a_dark_zone_and_a_lamp_change_the_line(floor):
    hall = _line(floor, TrackLighting())
    dark = _line(floor, TrackLighting(ambient_lux=50.0))
    lamp = _line(floor, TrackLighting(ambient_lux=50.0, lights=(Light(0.6, 0.0, 1.0, 600.0),)))
    assert dark[40] < 0.15 * hall[40]  # a tenth of the light: a tenth of the signal (+ black level)
    assert lamp[40] > 3 * dark[40]
    assert np.argmin(lamp) in range(60, 69)  # the black line is still there, in the middle


def test_a_tunnel_darkens_the_line_by_its_transmission(floor):
    black = CarDescription().camera.black_level_dn
    hall = _line(floor, TrackLighting())
    tunnel = _line(floor, TrackLighting(shades=(Shade(0.6, 0.0, 1.0, 2.0, 0.0, 0.2),)))
    lamp_in_tunnel = _line(floor, TrackLighting(ambient_lux=50.0, lights=(Light(0.6, 0.0, 1.0, 600.0),),
                                                shades=(Shade(0.6, 0.0, 1.0, 2.0, 0.0, 0.2),)))
    lamp = _line(floor, TrackLighting(ambient_lux=50.0, lights=(Light(0.6, 0.0, 1.0, 600.0),)))
    assert (tunnel[40] - black) / (hall[40] - black) == pytest.approx(0.2, abs=0.02)
    assert (lamp_in_tunnel[40] - black) / (lamp[40] - black) == pytest.approx(0.2, abs=0.02)


def test_reflectances_and_the_lamps_highlight(floor):
    base = _line(floor, TrackLighting(ambient_lux=300.0, specular=0.0))
    grey = _line(floor, TrackLighting(ambient_lux=300.0, lane_reflectance=0.46, specular=0.0))
    assert grey[30] == pytest.approx(4 + (base[30] - 4) * 0.46 / (235 / 255), abs=1.0)
    # a lamp behind the camera's view, its mirror image in the lane: a highlight with gloss only
    lamp = (Light(0.9, 0.0, 0.35, 30.0),)
    matte = _line(floor, TrackLighting(ambient_lux=0.0, lights=lamp, specular=0.0))
    glossy = _line(floor, TrackLighting(ambient_lux=0.0, lights=lamp, specular=0.3))
    gain = glossy - matte
    assert glossy.max() < 255 and (gain >= 0).all()
    assert gain[40:88].max() > 0.5 * matte[40:88].max()  # the highlight, where the mirror angle is
    assert gain[:10].max() <= 1 and gain[-10:].max() <= 1  # and nowhere else


def test_the_dim_hall_of_the_docs_defeats_a_fixed_threshold_not_an_adaptive_one(tmp_path):
    """docs/camera.md "A dim hall", as it says: the line follower with its fixed threshold
    leaves the track in the dim loop; with threshold=0 it laps, and the C twin logs the same."""
    from pathlib import Path

    from simrunner.run.runner import drive

    ex = Path(__file__).resolve().parents[1] / "examples"
    kw = dict(track=ex / "dim_hall.txt", laps=2)  # the default car: a linescan camera
    fixed = drive(ex / "line_follower.py", **kw)
    assert fixed.outcome == "off_track" and fixed.sim_time_s < 3.0
    adaptive = drive(ex / "line_follower.py", params={"threshold": 0}, csv=tmp_path / "py.csv", **kw)
    assert adaptive.outcome == "finished" and adaptive.laps_completed == 2
    twin = drive(ex / "line_follower.c", params={"threshold": 0}, csv=tmp_path / "c.csv", **kw)
    assert twin.outcome == "finished"
    assert (tmp_path / "py.csv").read_bytes() == (tmp_path / "c.csv").read_bytes()


def test_the_video_track_map_shows_the_light(floor):
    from simrunner.reports.video_frame import TrackView

    lamp = TrackLighting(ambient_lux=50.0, lights=(Light(2.0, 2.0, 1.5, 3000.0, 60.0),))
    plain = TrackView(floor, 200, 200).canvas
    lit = TrackView(floor, 200, 200, lamp, 0.0)
    under = lit.to_px(2.0, 2.0)
    away = lit.to_px(-5.0, -5.0)
    assert lit.canvas[under[1], under[0]].mean() == 255  # the lane under the spot, clipped white
    assert lit.canvas[away[1], away[0]].mean() < 0.15 * plain[away[1], away[0]].mean()  # 50 of 500 lux
    assert np.array_equal(TrackView(floor, 200, 200, TrackLighting(), 0.0).canvas, plain)


def test_the_tunnel_example_dims_its_straight_and_the_line_follower_laps_it():
    from simrunner.run.runner import drive

    examples = Path(__file__).resolve().parents[1] / "examples"
    track = load_track(examples / "tunnel.txt")
    shade, = track.lighting.shades
    assert shade.transmission == 0.15
    r = drive(examples / "line_follower.py", track=track, laps=1, seed=0)
    assert r.outcome == "finished", r.message
