"""worlds: SDF writing (track, car, world), reading (Scene), checking; NXP's real worlds."""
from __future__ import annotations

import math
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from pieces.pose import Pose2
from vehicle import CarDescription
from worlds import (MeshVisual, WorldError, check_world, load_mesh_world, read_world,
                    write_car_model, write_track_world)
from vehicle.description import Chassis, Drive, Steering, Wheels
from worlds.sdf_write import box_inertia, wheel_inertia
from worlds.sdf_xml import fmt, parse_pose, parse_xml, pose_matrix

TRACKS = Path(__file__).resolve().parents[2] / "shared" / "tracks"
HAS_IGN = shutil.which("ign") is not None
needs_ign = pytest.mark.skipif(not HAS_IGN, reason="libsdformat's `ign sdf` is not installed "
                               "(apt-get install libsdformat-dev ignition-tools)")
needs_tracks = pytest.mark.skipif(not TRACKS.is_dir(), reason=f"NXP tracks not found at {TRACKS}")

SURFACE_Z_M = 0.003
START = Pose2(0.5, 0.0, 0.1)


def _box(size, centre) -> trimesh.Trimesh:
    mesh = trimesh.creation.box(size)
    mesh.apply_translation(centre)
    return mesh


def _write_tiny_track(out: Path, car: CarDescription = CarDescription()) -> Path:
    """A 2 m x 0.5 m lane slab (z 0..3 mm), two edge lines and one marking, as STL files."""
    meshes_dir = out / "models" / "tiny" / "meshes"
    meshes_dir.mkdir(parents=True)
    t = SURFACE_Z_M
    _box((2.0, 0.5, t), (1.0, 0.0, t / 2)).export(meshes_dir / "lane.stl")
    edges = trimesh.util.concatenate([_box((2.0, 0.02, t), (1.0, y, t / 2)) for y in (0.26, -0.26)])
    edges.export(meshes_dir / "edges.stl")
    _box((0.02, 0.5, t), (1.9, 0.0, t / 2)).export(meshes_dir / "markings.stl")
    return write_track_world(out, track_name="tiny", start_pose=START, surface_z_m=t, car=car,
                             meshes={"lane": "meshes/lane.stl", "edges": "meshes/edges.stl",
                                     "markings": "meshes/markings.stl"})


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("tiny")
    world = _write_tiny_track(out)
    assert world == out / "world.sdf"
    return out


def _top_z_at(mesh: trimesh.Trimesh, xy) -> float | None:
    """Highest z of the mesh's triangles whose top-down projection contains ``xy``."""
    tri = mesh.triangles
    a, b, c = tri[:, 0, :2], tri[:, 1, :2], tri[:, 2, :2]
    q = np.asarray(xy, dtype=float)

    def cross(u, w):
        return u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]

    d1, d2, d3 = cross(b - a, q - a), cross(c - b, q - b), cross(a - c, q - c)
    inside = (((d1 >= 0) & (d2 >= 0) & (d3 >= 0)) | ((d1 <= 0) & (d2 <= 0) & (d3 <= 0)))
    inside &= np.abs(cross(b - a, c - a)) > 1e-12
    return float(tri[inside][:, :, 2].max()) if inside.any() else None


def _ign_k(path: Path, env=None) -> subprocess.CompletedProcess:
    return subprocess.run(["ign", "sdf", "-k", str(path)], capture_output=True, text=True, env=env,
                          timeout=120, check=False)


# -- generated world ---------------------------------------------------------------------------
def test_generated_folder_layout(tiny):
    for rel in ("world.sdf", "models/tiny/model.config", "models/tiny/model.sdf",
                "models/nxp_cup_car/model.config", "models/nxp_cup_car/model.sdf"):
        assert (tiny / rel).is_file(), rel
    for rel in ("world.sdf", "models/tiny/model.sdf", "models/nxp_cup_car/model.sdf"):
        assert parse_xml(tiny / rel).root.get("version") == "1.6"
    uris = [u.text for u in ET.parse(tiny / "models/tiny/model.sdf").getroot().iter("uri")]
    assert uris and all(u.startswith("model://tiny/meshes/") for u in uris)
    uris = [u.text for u in ET.parse(tiny / "world.sdf").getroot().iter("uri")]
    assert sorted(set(uris)) == ["models/tiny/meshes/edges.stl", "models/tiny/meshes/lane.stl",
                                 "models/tiny/meshes/markings.stl"]


@needs_ign
def test_generated_world_is_valid_for_libsdformat_without_environment(tiny):
    for rel in ("world.sdf", "models/tiny/model.sdf", "models/nxp_cup_car/model.sdf"):
        proc = _ign_k(tiny / rel)
        assert proc.returncode == 0 and "Valid." in proc.stdout, (rel, proc.stdout, proc.stderr)
    assert check_world(tiny) == []


def test_generated_world_loads_in_dartpy(tiny):
    dart = pytest.importorskip("dartpy")
    world = dart.utils.SdfParser.readWorld(dart.common.Uri("file://" + str(tiny / "world.sdf")))
    assert world is not None
    skeletons = {world.getSkeleton(i).getName(): world.getSkeleton(i) for i in range(world.getNumSkeletons())}
    assert sorted(skeletons) == ["ground_plane", "nxp_cup_car", "tiny"]
    shapes = [sn.getShape().getType() for sn in skeletons["tiny"].getBodyNode(0).getShapeNodes()]
    assert shapes.count("MeshShape") == 6  # 3 visuals + 3 collisions
    car = skeletons["nxp_cup_car"]
    assert car.getNumBodyNodes() == 7 and car.getNumJoints() == 7
    assert car.getMass() == pytest.approx(CarDescription().chassis.mass_kg, rel=1e-9)
    chassis = car.getBodyNode("chassis").getWorldTransform().translation()
    np.testing.assert_allclose(chassis, [START.x_m, START.y_m, SURFACE_Z_M], atol=1e-9)


def test_read_world_round_trip(tiny):
    scene = read_world(tiny)
    assert scene.source == tiny / "world.sdf"
    assert scene.car_pose is not None
    assert scene.car_pose.distance_to(START)[0] < 1e-12 and scene.car_pose.distance_to(START)[1] < 1e-12
    assert scene.car_z_m == pytest.approx(SURFACE_Z_M, abs=1e-12)
    assert scene.ground_z_m == 0.0 and scene.track_json is None
    roles = {v.role: v for v in scene.visuals}
    assert sorted(roles) == ["edge", "lane", "marking"] and len(scene.collisions) == 3
    np.testing.assert_array_equal(roles["lane"].rgba, [1, 1, 1, 1])
    np.testing.assert_array_equal(roles["edge"].rgba, [0, 0, 0, 1])
    np.testing.assert_array_equal(roles["marking"].rgba, [0, 0, 0, 1])
    for v in scene.visuals:
        assert v.mesh_path.resolve().parent == (tiny / "models/tiny/meshes").resolve()
        np.testing.assert_array_equal(v.world_from_mesh, np.eye(4))
        np.testing.assert_array_equal(v.scale, [1, 1, 1])
    lane = load_mesh_world(roles["lane"])
    np.testing.assert_allclose(lane.bounds, [[0, -0.25, 0], [2, 0.25, SURFACE_Z_M]], atol=1e-6)
    assert _top_z_at(lane, (START.x_m, START.y_m)) == pytest.approx(SURFACE_Z_M, abs=1e-6)


def test_read_model_folder_resolves_model_uris(tiny):
    scene = read_world(tiny / "models" / "tiny")
    assert scene.source.name == "model.sdf" and scene.car_pose is None
    assert sorted(v.role for v in scene.visuals) == ["edge", "lane", "marking"]
    car = read_world(tiny / "models" / "nxp_cup_car")
    assert car.car_pose == Pose2() and car.visuals == ()


def test_track_json_beside_world_is_reported(tmp_path):
    _write_tiny_track(tmp_path)
    (tmp_path / "track.json").write_text("{}")
    assert read_world(tmp_path / "world.sdf").track_json == tmp_path / "track.json"


def test_write_track_world_rejects_bad_input(tmp_path):
    meshes_dir = tmp_path / "models" / "t" / "meshes"
    meshes_dir.mkdir(parents=True)
    _box((1, 1, 0.003), (0, 0, 0.0015)).export(meshes_dir / "lane.stl")
    kw = dict(start_pose=Pose2(), car=CarDescription())
    with pytest.raises(WorldError, match=r"lane top at z = 0\.003000 m, expected surface_z_m = 0\.010000"):
        write_track_world(tmp_path, track_name="t", meshes={"lane": "meshes/lane.stl"}, surface_z_m=0.01, **kw)
    with pytest.raises(WorldError, match=r"edges mesh file not found"):
        write_track_world(tmp_path, track_name="t", surface_z_m=0.003, **kw,
                          meshes={"lane": "meshes/lane.stl", "edges": "meshes/edges.stl"})
    with pytest.raises(WorldError, match=r"unknown mesh role 'road'"):
        write_track_world(tmp_path, track_name="t", meshes={"lane": "meshes/lane.stl", "road": "x"},
                          surface_z_m=0.003, **kw)
    with pytest.raises(WorldError, match=r"track model name 'my track'"):
        write_track_world(tmp_path, track_name="my track", meshes={"lane": "meshes/lane.stl"},
                          surface_z_m=0.003, **kw)
    assert not (tmp_path / "world.sdf").exists()


# -- reading other people's worlds -----------------------------------------------------------------
@needs_tracks
@pytest.mark.parametrize("name, include_xyz", [("nxp_raceway", (-0.7, -0.3, -0.04)),
                                               ("nxp_raceway_octagon", (-4.0, -0.275, -0.04))])
def test_nxp_worlds(name, include_xyz):
    scene = read_world(TRACKS / name)
    assert scene.source == TRACKS / name / f"{name}.world"
    assert scene.car_pose is None and scene.car_z_m is None and scene.ground_z_m == 0.0
    by_role = {v.role: v for v in scene.visuals}
    assert sorted(by_role) == ["edge", "lane"] and len(scene.collisions) == 1
    lane, edge = by_role["lane"], by_role["edge"]
    assert (lane.material_name, edge.material_name) == ("Gazebo/White", "Gazebo/Black")
    np.testing.assert_array_equal(lane.rgba, [1, 1, 1, 1])
    np.testing.assert_array_equal(edge.rgba, [0, 0, 0, 1])
    np.testing.assert_allclose(lane.world_from_mesh[:3, 3], include_xyz, atol=1e-12)
    np.testing.assert_allclose(edge.world_from_mesh[:3, 3], np.add(include_xyz, (-0.02, -0.02, 0)), atol=1e-12)
    lane_mesh, edge_mesh = load_mesh_world(lane), load_mesh_world(edge)
    assert lane_mesh.bounds[1, 2] == pytest.approx(0.01, abs=1e-6)
    # The car's start (world origin, heading +x) stands on the white lane, not on a line.
    for x in (0.0, 0.2):
        assert _top_z_at(lane_mesh, (x, 0.0)) == pytest.approx(0.01, abs=1e-6)
    assert _top_z_at(edge_mesh, (0.0, 0.0)) is None
    assert check_world(TRACKS / name) == []


@needs_tracks
def test_nxp_model_folder_and_model_file():
    model = read_world(TRACKS / "nxp_raceway" / "nxp_raceway.sdf")
    border = next(v for v in model.visuals if v.role == "edge")
    np.testing.assert_allclose(border.world_from_mesh[:3, 3], (-0.02, -0.02, 0), atol=1e-12)
    assert model.ground_z_m is None


def _mini_model(root: Path, name: str = "mini", visual_pose: str = "0 0 0 0 0 0",
                scale: str = "1 1 1", material: str = "<diffuse>0.2 0.4 0.6 1</diffuse>") -> Path:
    model_dir = root / name
    (model_dir / "meshes").mkdir(parents=True)
    _box((1, 1, 0.1), (0, 0, 0.05)).export(model_dir / "meshes" / "slab.stl")
    (model_dir / "model.config").write_text(
        f'<?xml version="1.0"?><model><name>{name}</name><sdf version="1.5">m.sdf</sdf></model>')
    (model_dir / "m.sdf").write_text(f"""<?xml version="1.0"?>
<sdf version="1.5"><model name="{name}"><pose>5 5 5 0 0 0</pose>
  <link name="l"><pose>1 0 0 0 0 {math.pi / 2}</pose>
    <visual name="v"><pose>{visual_pose}</pose>
      <geometry><mesh><uri>model://{name}/meshes/slab.stl</uri><scale>{scale}</scale></mesh></geometry>
      <material>{material}</material></visual></link></model></sdf>""")
    return model_dir


def _include_world(path: Path, name: str = "mini", pose: str = "1 2 0.5 0 0 1.5707963267948966") -> Path:
    path.write_text(f"""<?xml version="1.0"?>
<sdf version="1.6"><world name="w">
  <include><uri>model://ground_plane</uri><pose>0 0 -0.5 0 0 0</pose></include>
  <include><uri>model://{name}</uri><pose>{pose}</pose></include>
</world></sdf>""")
    return path


def test_include_pose_composition_scale_and_colour(tmp_path):
    _mini_model(tmp_path / "models", visual_pose="0.5 0 0 0 0 0", scale="2 1 1")
    scene = read_world(_include_world(tmp_path / "w.world"))
    assert scene.ground_z_m == -0.5
    (v,) = scene.visuals
    expected = (pose_matrix(1, 2, 0.5, 0, 0, math.pi / 2) @ pose_matrix(1, 0, 0, 0, 0, math.pi / 2)
                @ pose_matrix(0.5, 0, 0, 0, 0, 0))  # include (replaces model pose) . link . visual
    np.testing.assert_allclose(v.world_from_mesh, expected, atol=1e-12)
    np.testing.assert_array_equal(v.scale, [2, 1, 1])
    np.testing.assert_allclose(v.rgba, [0.2, 0.4, 0.6, 1])
    assert v.material_name is None and v.role == "other"
    mesh = load_mesh_world(v)  # a 2 m x 1 m slab turned 180 deg in total
    centre = expected @ np.array([0, 0, 0.05, 1])
    np.testing.assert_allclose(mesh.bounds.mean(axis=0), centre[:3], atol=1e-6)
    np.testing.assert_allclose(np.ptp(mesh.bounds, axis=0), [2, 1, 0.1], atol=1e-6)


def test_model_found_via_environment_path(tmp_path, monkeypatch):
    _mini_model(tmp_path / "elsewhere", name="faraway", material="<script><name>Gazebo/Black</name></script>")
    (tmp_path / "w").mkdir()
    world = _include_world(tmp_path / "w" / "w.world", name="faraway")
    with pytest.raises(WorldError, match=r"w\.world:4: model 'faraway' not found"):
        read_world(world)
    monkeypatch.setenv("GAZEBO_MODEL_PATH", str(tmp_path / "elsewhere"))
    (v,) = read_world(world).visuals
    np.testing.assert_array_equal(v.rgba, [0, 0, 0, 1])
    assert v.material_name == "Gazebo/Black" and v.role == "edge"


# -- errors ------------------------------------------------------------------------------------------
BAD_FILES = {
    "bad_xml.sdf": ('<?xml version="1.0"?>\n<sdf version="1.6">\n<world name="w">\n</sdf>\n',
                    r"bad_xml\.sdf:4: invalid XML"),
    "bad_pose.sdf": ('<?xml version="1.0"?>\n<sdf version="1.6"><world name="w">\n<model name="m">\n'
                     '<pose>1 2 x 0 0 0</pose></model></world></sdf>\n',
                     r"bad_pose\.sdf:4: <pose> '1 2 x 0 0 0' is not 6 finite numbers"),
    "short_pose.sdf": ('<sdf version="1.6"><world name="w"><model name="m"><pose>1 2 3</pose>'
                       '</model></world></sdf>', r"short_pose\.sdf:1: <pose> '1 2 3' is not 6"),
    "no_model.sdf": ('<sdf version="1.6"><world name="w">\n<include><uri>model://nowhere_xyz</uri>'
                     '</include></world></sdf>', r"no_model\.sdf:2: model 'nowhere_xyz' not found"),
    "no_mesh.sdf": ('<sdf version="1.6"><world name="w"><model name="m"><link name="l">\n'
                    '<visual name="v"><geometry><mesh>\n<uri>missing.stl</uri></mesh></geometry>'
                    '</visual></link></model></world></sdf>',
                    r"no_mesh\.sdf:3: mesh file .*missing\.stl not found"),
    "not_sdf.sdf": ('<robot name="r"/>', r"not_sdf\.sdf:1: expected <sdf> as the root element"),
    "empty.sdf": ('<sdf version="1.6"/>', r"empty\.sdf:1: expected a <world> or <model>"),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_errors_are_one_line_with_file_and_line(tmp_path, name):
    text, pattern = BAD_FILES[name]
    (tmp_path / name).write_text(text)
    with pytest.raises(WorldError, match=pattern) as info:
        read_world(tmp_path / name)
    assert "\n" not in str(info.value) and str(tmp_path / name) in str(info.value)
    # Without ign, check_world looks at the XML, includes, mesh files and versions only.
    problems = check_world(tmp_path / name, use_ign=False)
    if name in ("bad_pose.sdf", "short_pose.sdf", "empty.sdf"):
        assert problems == []
    else:
        assert problems and all("\n" not in p and name in p for p in problems)


def test_missing_world_and_empty_folder(tmp_path):
    with pytest.raises(WorldError, match=r"nothing\.sdf: world file or folder not found"):
        read_world(tmp_path / "nothing.sdf")
    with pytest.raises(WorldError, match=r"expected world\.sdf, one \*\.world file or model\.config"):
        read_world(tmp_path)


def test_check_world_reports_missing_mesh_and_new_version(tmp_path):
    out = tmp_path / "t"
    _write_tiny_track(out)
    (out / "models/tiny/meshes/edges.stl").unlink()
    problems = check_world(out, use_ign=False)
    assert len(problems) == 2, problems  # world.sdf: the visual and the collision
    assert all("edges.stl not found" in p and "world.sdf:" in p for p in problems)
    new = tmp_path / "new.sdf"
    new.write_text('<sdf version="1.9"><world name="w"/></sdf>')
    assert check_world(new, use_ign=False) == [
        f"{new}:1: SDF version 1.9: expected 1.4 .. 1.6 (dartpy's SdfParser reads no other)"]


@needs_ign
def test_check_world_reports_ign_errors(tmp_path):
    dup = tmp_path / "dup.sdf"
    dup.write_text('<sdf version="1.6"><world name="w"><model name="a"><static>1</static>'
                   '<link name="l"/></model><model name="a"><static>1</static><link name="l"/></model>'
                   '</world></sdf>')
    problems = check_world(dup)
    assert problems and all(p.startswith(f"{dup}: ign sdf -k: Error Code") for p in problems)


# -- poses: property tests ------------------------------------------------------------------------------
finite = st.floats(-1e3, 1e3, allow_nan=False)
angle = st.floats(-math.pi, math.pi, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(finite, finite, finite, angle, angle, angle)
def test_pose_text_round_trip(x, y, z, roll, pitch, yaw):
    el = ET.Element("pose")
    el.text = fmt(x, y, z, roll, pitch, yaw)
    doc = type("Doc", (), {"error": lambda self, e, m: WorldError(m)})()
    m = parse_pose(doc, el)
    assert np.array_equal(m, pose_matrix(x, y, z, roll, pitch, yaw))
    np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)


def test_pose_convention_extrinsic_xyz():
    # yaw turns +x to +y; positive pitch turns +x down (-z); roll turns +y to +z.
    np.testing.assert_allclose(pose_matrix(yaw=math.pi / 2)[:3, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(pose_matrix(pitch=math.pi / 2)[:3, 0], [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(pose_matrix(roll=math.pi / 2)[:3, 1], [0, 0, 1], atol=1e-15)
    r = pose_matrix(roll=0.3, pitch=0.2, yaw=0.1)[:3, :3]
    np.testing.assert_allclose(r, pose_matrix(yaw=0.1)[:3, :3] @ pose_matrix(pitch=0.2)[:3, :3]
                               @ pose_matrix(roll=0.3)[:3, :3], atol=1e-15)


@settings(max_examples=100, deadline=None)
@given(st.text(alphabet="0123456789.-e x\tnaif", max_size=40))
def test_pose_parser_raises_only_world_error(text):
    el = ET.Element("pose")
    el.text = text
    doc = type("Doc", (), {"error": lambda self, e, m: WorldError(m)})()
    try:
        m = parse_pose(doc, el)
    except WorldError as exc:
        assert "\n" not in str(exc)
    else:
        assert m.shape == (4, 4) and np.isfinite(m).all()


@settings(max_examples=15, deadline=None)
@given(st.floats(-50, 50), st.floats(-50, 50), angle, st.floats(0, 0.1))
def test_car_pose_round_trip(tmp_path_factory, x, y, yaw, z):
    out = tmp_path_factory.mktemp("pose")
    car_dir = out / "models" / "nxp_cup_car"
    write_car_model(car_dir, CarDescription())
    (out / "w.sdf").write_text(
        f'<sdf version="1.6"><world name="w"><include><uri>model://nxp_cup_car</uri>'
        f'<pose>{fmt(x, y, z, 0, 0, yaw)}</pose></include></world></sdf>')
    scene = read_world(out / "w.sdf")
    d_m, d_rad = scene.car_pose.distance_to(Pose2(x, y, yaw))
    assert d_m < 1e-9 and d_rad < 1e-9 and scene.car_z_m == pytest.approx(z, abs=1e-12)


# -- the car model ---------------------------------------------------------------------------------
CARS = {
    "default": CarDescription(),
    "other": CarDescription(chassis=Chassis(mass_kg=1.7, wheelbase_m=0.21, track_m=0.18),
                            wheels=Wheels(radius_m=0.041, width_m=0.03, mass_kg=0.06, friction_mu=0.8),
                            steering=Steering(limit_rad=0.35, rate_radps=5.0),
                            drive=Drive(max_speed_mps=2.5, max_accel_mps2=2.0, max_brake_mps2=3.5),
                            name="car_b"),
}


def _num(el: ET.Element, path: str) -> float:
    found = el.find(path)
    assert found is not None, path
    return float(found.text)


def _vec(el: ET.Element, path: str) -> np.ndarray:
    return np.array([float(v) for v in el.find(path).text.split()])


@pytest.mark.parametrize("key", sorted(CARS))
def test_car_model_numbers_match_description(tmp_path, key):
    car = CARS[key]
    write_car_model(tmp_path / car.name, car)
    if HAS_IGN:
        proc = _ign_k(tmp_path / car.name / "model.sdf")
        assert proc.returncode == 0 and "Valid." in proc.stdout, proc.stderr
    config = ET.parse(tmp_path / car.name / "model.config").getroot()
    assert config.find("sdf").text == "model.sdf" and config.find("sdf").get("version") == "1.6"
    model = ET.parse(tmp_path / car.name / "model.sdf").getroot().find("model")
    assert model.get("name") == car.name
    links = {link.get("name"): link for link in model.findall("link")}
    joints = {j.get("name"): j for j in model.findall("joint")}
    c, w = car.chassis, car.wheels
    r = w.radius_m
    positions = {n: _vec(links[n], "pose")[:3] for n in ("wheel_fl", "wheel_fr", "wheel_rl", "wheel_rr")}
    np.testing.assert_allclose(positions["wheel_fl"], [c.wheelbase_m, c.track_m / 2, r])
    np.testing.assert_allclose(positions["wheel_rr"], [0, -c.track_m / 2, r])
    for n in positions:
        assert _num(links[n], "collision/geometry/cylinder/radius") == r
        assert _num(links[n], "collision/geometry/cylinder/length") == w.width_m
        assert _num(links[n], "collision/surface/friction/ode/mu") == w.friction_mu
        assert _num(links[n], "inertial/mass") == w.mass_kg
        inertia = [_num(links[n], f"inertial/inertia/{k}") for k in ("ixx", "iyy", "izz")]
        np.testing.assert_allclose(inertia, wheel_inertia(w.mass_kg, r, w.width_m), rtol=1e-15)
        assert joints[f"{n}_joint"].find("axis/xyz").text == "0 1 0"
    assert joints["wheel_fl_joint"].find("parent").text == "knuckle_l"
    assert joints["wheel_rl_joint"].find("parent").text == "chassis"
    total = sum(_num(link, "inertial/mass") for link in links.values())
    assert total == pytest.approx(c.mass_kg, rel=1e-12)
    box = _vec(links["chassis"], "collision/geometry/box/size")
    np.testing.assert_allclose(box, [c.length_m, c.width_m, c.height_m])
    body_kg = _num(links["chassis"], "inertial/mass")
    np.testing.assert_allclose([_num(links["chassis"], f"inertial/inertia/{k}") for k in ("ixx", "iyy", "izz")],
                               box_inertia(body_kg, tuple(box)), rtol=1e-15)
    # Steering joints: the inner wheel's angle at the bicycle limit (Ackermann geometry).
    a, L, t = car.steering.limit_rad, c.wheelbase_m, c.track_m
    inner = math.atan(L / (L / math.tan(a) - t / 2))
    for side in "lr":
        j = joints[f"steer_{side}_joint"]
        assert j.find("axis/xyz").text == "0 0 1"
        assert _num(j, "axis/limit/upper") == pytest.approx(inner, abs=1e-12)
        assert _num(j, "axis/limit/lower") == pytest.approx(-inner, abs=1e-12)
        assert _num(j, "axis/limit/velocity") == car.steering.rate_radps
    plugins = {p.get("name"): p for p in model.findall("plugin")}
    ack = plugins["gz::sim::systems::AckermannSteering"]
    assert ack.get("filename") == "gz-sim-ackermann-steering-system"
    assert ack.find("steering_only").text == "true" and ack.find("topic").text == "/steer_angle"
    assert (ack.find("left_steering_joint").text, ack.find("right_steering_joint").text) == \
        ("steer_l_joint", "steer_r_joint")
    assert _num(ack, "wheel_base") == L and _num(ack, "wheel_separation") == t
    assert _num(ack, "steering_limit") == a and _num(ack, "wheel_radius") == r
    assert _num(ack, "steer_cmd_max") == car.steering.rate_radps
    diff = plugins["gz::sim::systems::DiffDrive"]
    assert diff.get("filename") == "gz-sim-diff-drive-system" and diff.find("topic").text == "/cmd_vel"
    assert (diff.find("left_joint").text, diff.find("right_joint").text) == ("wheel_rl_joint", "wheel_rr_joint")
    d = car.drive
    assert [_num(diff, k) for k in ("wheel_separation", "wheel_radius", "min_linear_velocity",
                                    "max_linear_velocity", "min_linear_acceleration",
                                    "max_linear_acceleration")] == \
        [t, r, -d.max_speed_mps, d.max_speed_mps, -d.max_brake_mps2, d.max_accel_mps2]
    sensor = links["chassis"].find("sensor")
    cam = car.camera
    assert sensor.get("type") == "camera"
    np.testing.assert_allclose(_vec(sensor, "pose"), [cam.forward_m, 0, cam.height_m, 0, cam.pitch_rad, 0])
    assert _num(sensor, "update_rate") == cam.fps_hz
    assert _num(sensor, "camera/horizontal_fov") == cam.hfov_rad
    assert (_num(sensor, "camera/image/width"), _num(sensor, "camera/image/height")) == \
        (cam.width_px, cam.height_px)


def test_car_model_rejects_impossible_masses(tmp_path):
    from vehicle.description import CarDescriptionError

    car = CarDescription(chassis=Chassis(mass_kg=0.1), wheels=Wheels(mass_kg=0.05))
    with pytest.raises(CarDescriptionError, match=r"chassis\.mass_kg = 0\.1 must exceed"):
        write_car_model(tmp_path / "c", car)


def test_mesh_visual_is_read_only(tiny):
    v: MeshVisual = read_world(tiny).visuals[0]
    with pytest.raises(ValueError):
        v.world_from_mesh[0, 0] = 2.0


def test_worlds_does_not_import_dartpy():
    code = ("import sys, worlds; from worlds import read_world, write_track_world, check_world; "
            "import worlds.sdf_write, worlds.sdf_read, worlds.check; "
            "assert 'dartpy' not in sys.modules, 'dartpy imported'")
    subprocess.run([__import__("sys").executable, "-c", code], check=True, timeout=120)
