"""Track loading (simrunner.track.load): layouts in memory, every world through worlds.sdf_read;
raster, start, gate; both routes give the same track."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pieces.pose import Pose2
from simrunner.errors import SimError
from simrunner.track.raster import BLACK_GRAY, FLOOR_GRAY, WHITE_GRAY
from simrunner.track.load import TrackLoadError, load_track, road_extents_m, track_from_trackgen

REPO = Path(__file__).resolve().parents[1]
TRACKS = REPO.parent / "shared" / "tracks"
OVAL = """@name = oval
START_FINISH
STRAIGHT
TURN_LEFT x4
STRAIGHT x2
TURN_LEFT x4
"""


def need_nxp(name: str) -> Path:
    folder = TRACKS / name
    if not folder.is_dir():
        pytest.skip(f"NXP tracks not found at {TRACKS} (expected beside the checkout)")
    return folder


def cross_section(track, pose: Pose2, half_m: float = 0.32) -> np.ndarray:
    """Gray values along the pose's lateral axis, left to right, every 0.01 m."""
    ys = np.arange(half_m, -half_m - 1e-9, -0.01)
    return track.raster.gray_at(pose.apply(np.column_stack((np.zeros_like(ys), ys))))


@pytest.fixture(scope="module")
def oval_folder(tmp_path_factory):
    from trackgen.build import build

    tmp = tmp_path_factory.mktemp("oval")
    layout = tmp / "oval.txt"
    layout.write_text(OVAL)
    build(layout, tmp / "out")
    return tmp


@pytest.mark.parametrize("name, spec", [("nxp_raceway", ""), ("nxp_raceway", "nxp_raceway.world"),
                                        ("nxp_raceway_octagon", "")])
def test_nxp_tracks_load_with_start_at_origin_on_the_lane(name, spec):
    folder = need_nxp(name)
    track = load_track(folder / spec if spec else folder)
    assert track.name == name
    assert track.start == Pose2() and track.gate == Pose2()
    # the .world's include pose is applied: slab 0..0.05 m lowered by 0.04 m
    assert track.surface_z_m == pytest.approx(0.01, abs=1e-6)
    # white lane at the start, a black line, then the floor on both sides
    section = cross_section(track, track.start)
    assert section[len(section) // 2] == WHITE_GRAY
    for side in (section[: len(section) // 2], section[len(section) // 2:][::-1]):
        assert list(dict.fromkeys(side.tolist())) == [FLOOR_GRAY, BLACK_GRAY, WHITE_GRAY]
    # road ~0.555 m edge to edge (PROVENANCE.md: 0.55 m lane incl. 0.02 m lines; 5 mm pixels)
    left, right = road_extents_m(track.raster, track.start)
    assert left + right == pytest.approx(0.555, abs=0.01)
    assert track.gate_half_width_m == pytest.approx(max(left, right))
    assert track.lap_length_estimated and track.centreline is None


def test_nxp_raceway_lap_length_estimate_and_start_on_road():
    track = load_track(need_nxp("nxp_raceway"))
    assert track.raster.on_road([[0.0, 0.0]])[0]
    # road area / road width; the centreline of NXP's raceway measures ~23-24 m
    assert 20.0 < track.lap_length_m < 27.0


def test_border_lines_sit_on_the_lane_edges():
    """NXP's border visual has pose -.02 -.02: applied, each black line touches the white lane
    (no floor between them) along the whole track."""
    track = load_track(need_nxp("nxp_raceway"))
    img = track.raster.image
    white = img == WHITE_GRAY

    def white_next_to(other):  # 4-neighbour pixel pairs (white, other)
        return ((white[1:, :] & other[:-1, :]).sum() + (white[:-1, :] & other[1:, :]).sum()
                + (white[:, 1:] & other[:, :-1]).sum() + (white[:, :-1] & other[:, 1:]).sum())

    boundary = white_next_to(~white)
    # Measured: 115 of 10596 boundary pairs touch the floor (mesh sliver gaps up to 4 mm);
    # without the -.02 -.02 border pose it is 6195 of 13188.
    assert white_next_to(img == FLOOR_GRAY) < 0.02 * boundary


def test_layout_file_is_loaded_in_memory(oval_folder):
    track = load_track(oval_folder / "oval.txt")
    data = json.loads((oval_folder / "out" / "track.json").read_text())
    assert track.name == "oval" and track.source == oval_folder / "oval.txt"
    gate = data["finish_gate"]
    assert track.gate == Pose2(*gate["pose"]) and track.gate_half_width_m == gate["half_width_m"]
    assert track.lap_length_m == pytest.approx(data["length_m"]) and not track.lap_length_estimated
    assert track.centreline.shape[1] == 2
    # START_FINISH starts the car 0.3 m behind the gate; the black bar lies across the gate
    dist, dyaw = track.start.distance_to(track.gate)
    assert dist == pytest.approx(0.3, abs=1e-9) and dyaw == pytest.approx(0.0, abs=1e-12)
    assert track.raster.gray_at([[track.gate.x_m, track.gate.y_m]])[0] == BLACK_GRAY
    assert track.raster.gray_at([[track.start.x_m, track.start.y_m]])[0] == WHITE_GRAY
    assert track.surface_z_m == pytest.approx(data["surface_z_m"], abs=1e-6)


def test_trackgen_folder_and_world_file_give_the_same_track(oval_folder):
    a = load_track(oval_folder / "out")
    b = load_track(oval_folder / "out" / "world.sdf")
    c = load_track(oval_folder / "oval.txt")
    for t in (b, c):
        assert np.array_equal(a.raster.image, t.raster.image)
        assert a.raster.origin_xy_m == t.raster.origin_xy_m
        assert (a.start, a.gate, a.lap_length_m) == (t.start, t.gate, t.lap_length_m)


@pytest.mark.parametrize("spec, message", [
    ("missing_dir", "not found"),
    ("notes.md", "not a track"),
    ("empty_dir", "expected world.sdf"),
])
def test_bad_specs_raise_one_clear_error(tmp_path, spec, message):
    (tmp_path / "notes.md").write_text("hello")
    (tmp_path / "empty_dir").mkdir()
    with pytest.raises(TrackLoadError, match=message) as info:
        load_track(tmp_path / spec)
    assert isinstance(info.value, SimError) and str(tmp_path) in str(info.value)


def test_bad_layout_raises_track_load_error_with_line(tmp_path):
    layout = tmp_path / "bad.txt"
    layout.write_text("STRAIGHT\nTRUN_LEFT\n")
    with pytest.raises(TrackLoadError, match=r"bad.txt:2: .*TRUN_LEFT"):
        load_track(layout)


def test_model_file_without_start_on_the_road_is_refused():
    folder = need_nxp("nxp_raceway")
    with pytest.raises(TrackLoadError, match=r"start pose \(0.000, 0.000\) m .*world origin.* not on the track"):
        load_track(folder / "nxp_raceway.sdf")


@pytest.mark.parametrize("patch, message", [
    ({"start_pose": [0, 0]}, "start_pose: expected"),
    ({"finish_gate": {"pose": [0, 0, 0], "half_width_m": -1}}, "finish_gate: expected"),
    ({"length_m": "long"}, "length_m: expected"),
    ({"centreline": [[0, 0], [1]]}, "centreline: expected"),
    ({"format": "other"}, "nxpcup-track/1"),
])
def test_bad_track_json_is_reported(oval_folder, tmp_path, patch, message):
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(oval_folder / "out", out)
    data = json.loads((out / "track.json").read_text())
    data.update(patch)
    (out / "track.json").write_text(json.dumps(data))
    with pytest.raises(TrackLoadError, match=message) as info:
        load_track(out)
    assert "track.json" in str(info.value)


def test_start_pose_on_road_is_consistent_with_gate_heading(oval_folder):
    track = load_track(oval_folder / "out")
    ahead = track.start @ Pose2(0.3, 0.0, 0.0)
    assert ahead.distance_to(track.gate)[0] == pytest.approx(0.0, abs=1e-9)
    assert math.isclose(track.gate_half_width_m, 0.55 / 2 + 0.02, abs_tol=1e-9)


def test_unreadable_mesh_is_reported(oval_folder, tmp_path):
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(oval_folder / "out", out)
    mesh = next(out.glob("models/oval/meshes/lane*"))
    mesh.write_bytes(b"solid nonsense\nfacet normal 1 2\n")
    with pytest.raises(TrackLoadError, match=r"lane\.stl:2: ASCII STL: expected 'facet normal NX NY NZ'"):
        load_track(out)


# -- layouts in memory vs their built world ---------------------------------------------------
# An octagon of 1 m sides with the START_FINISH on the side at 135 deg: a rotated marking
# and a start pose whose yaw the built world stores through a rotation matrix.
OCTAGON = "@name = octagon_start\n" + "".join(
    f"{'START_FINISH' if side == 3 else 'STRAIGHT'}\nTURN_LEFT\n" for side in range(8))


@pytest.fixture(params=["examples/thesis_figure8.txt", "examples/oval_start.txt", "octagon"])
def layout_path(request, tmp_path):
    if request.param == "octagon":
        path = tmp_path / "octagon_start.txt"
        path.write_text(OCTAGON)
        return path
    return REPO / request.param


def test_layout_in_memory_equals_its_built_world(layout_path, tmp_path):
    """Issue 9: the simulator makes a layout's track in memory (raster from the polygons); the
    same layout built by ``trackgen build`` and read from its world gives the same track, the
    raster pixel for pixel (both paint the same triangles: raster.py, "Footprint layers")."""
    from trackgen.build import build

    build(layout_path, tmp_path / "built", preview=False)
    mem = load_track(layout_path)
    disk = load_track(tmp_path / "built")
    a, b = mem.raster, disk.raster
    assert (a.shape, a.origin_xy_m, a.m_per_px) == (b.shape, b.origin_xy_m, b.m_per_px)
    assert int(np.count_nonzero(a.image != b.image)) == 0
    assert int(np.count_nonzero(a.road_mask != b.road_mask)) == 0
    assert (mem.start, mem.gate, mem.gate_half_width_m) == (disk.start, disk.gate, disk.gate_half_width_m)
    assert mem.lap_length_m == disk.lap_length_m and not mem.lap_length_estimated
    assert np.array_equal(mem.centreline, disk.centreline)
    assert mem.surface_z_m == disk.surface_z_m  # the slab's top as float32, in both
    assert mem.name == disk.name and mem.source == layout_path


def test_layout_is_loaded_without_files_or_meshes(tmp_path):
    """No trackgen build, no world read, no STL: trimesh (and scipy, numpy-stl) stay unloaded."""
    code = (
        "import sys\n"
        "import simrunner.track.load as load, trackgen.build as build\n"
        "def refuse(*a, **k): raise AssertionError('touched the disk route')\n"
        "build.build = load._read_world = refuse\n"
        f"track = load.load_track({str(REPO / 'examples' / 'oval_start.txt')!r})\n"
        "print(track.name, sorted(m for m in ('trimesh', 'scipy', 'stl') if m in sys.modules))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=tmp_path, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["oval_start", "[]"]
    assert list(tmp_path.iterdir()) == []


def test_track_from_trackgen_takes_a_python_built_track():
    from trackgen import TrackGenerator

    gen = TrackGenerator(name="py_oval").add_piece("START_FINISH").add_piece("STRAIGHT")
    for _ in range(4):
        gen.add_piece("TURN_LEFT")
    gen.add_piece("STRAIGHT", length_m=2.0)
    for _ in range(4):
        gen.add_piece("TURN_LEFT")
    track = track_from_trackgen(gen.build())
    assert track.name == "py_oval" and track.source == Path(__file__)
    assert track.lap_length_m == pytest.approx(4.0 + 2 * math.pi * 0.8)
    assert track.raster.gray_at([[track.gate.x_m, track.gate.y_m]])[0] == BLACK_GRAY
    assert track.centreline.shape[1] == 2 and not track.centreline.flags.writeable


def test_failing_layout_raises_what_trackgen_build_raises(tmp_path):
    """Same one-line ``file:line: ...`` message as ``trackgen build``; its error is the cause."""
    from trackgen.build import ValidationFailed, build

    broken = REPO / "examples" / "broken.txt"
    with pytest.raises(ValidationFailed) as built:
        build(broken, tmp_path / "out", preview=False)
    with pytest.raises(TrackLoadError) as loaded:
        load_track(broken)
    assert str(loaded.value) == str(built.value)
    assert str(loaded.value).startswith(f"{broken}:12: track does not close")
    assert isinstance(loaded.value.__cause__, ValidationFailed)


def test_layout_named_like_the_car_is_refused(tmp_path):
    layout = tmp_path / "car.txt"
    layout.write_text("@name = nxp_cup_car\n" + OVAL.split("\n", 1)[1])
    with pytest.raises(TrackLoadError, match=r"car.txt: track name 'nxp_cup_car' equals the car"):
        load_track(layout)


@pytest.mark.parametrize("m_per_px", [0.0, -0.005, float("nan"), float("inf"), "5mm", True])
def test_bad_m_per_px_is_reported(oval_folder, m_per_px):
    for spec in (oval_folder / "oval.txt", oval_folder / "out"):
        with pytest.raises(TrackLoadError, match=r"m_per_px = .*: expected a positive number") as info:
            load_track(spec, m_per_px=m_per_px)
        assert str(spec) in str(info.value)
