"""Write Gazebo model folders and SDF 1.6 worlds (XML via ``xml.etree.ElementTree``).

Layout written by :func:`write_track_world` (the trackgen output folder)::

    OUT/world.sdf                         the world: ground, sun, track, car on the start pose
    OUT/models/<track>/model.config       Gazebo model folder of the track (static)
    OUT/models/<track>/model.sdf          mesh URIs model://<track>/meshes/<role>.stl
    OUT/models/<track>/meshes/*.stl       written by trackgen before calling us
    OUT/models/<car>/model.config         the Ackermann car from vehicle.description.CarDescription
    OUT/models/<car>/model.sdf

How world.sdf references the models (decided by experiment, libsdformat 12 / dartpy 6.20):
the track and car models are INLINED into world.sdf (copies of the ``<model>`` elements of
the model folders) and their mesh URIs are rewritten to paths RELATIVE to world.sdf
(``models/<track>/meshes/lane.stl``). Reason: dartpy's ``SdfParser.readWorld`` ignores
``<include>`` (it loads 0 skeletons), and ``ign sdf -k`` only resolves ``model://`` with
``SDF_PATH`` set; the inlined world is ``Valid.`` with no environment and loads in dartpy
with the meshes as MeshShape. The model folders stay for Gazebo users (insert / include).

Opening in Gazebo:

* gz-sim (Fortress and later): ``gz sim OUT/world.sdf`` (Fortress: ``ign gazebo OUT/world.sdf``).
  Relative mesh URIs are resolved against the world file's folder. The car listens on
  ``/steer_angle`` (gz.msgs.Double, radians, AckermannSteering in steering-only mode) and
  ``/cmd_vel`` (gz.msgs.Twist, DiffDrive on the rear wheels), as in the thesis (3.1, 3.2).
* To use the model folders elsewhere (``<include><uri>model://<track></uri></include>`` or
  the insert panel): ``export GZ_SIM_RESOURCE_PATH=OUT/models`` (Fortress:
  ``IGN_GAZEBO_RESOURCE_PATH``; Gazebo classic: ``GAZEBO_MODEL_PATH``; libsdformat's
  ``ign sdf -k``: ``SDF_PATH``).

Car model frames (same as ``simrunner.car.body``): the chassis link frame is the car body
frame (origin at the rear-axle midpoint on the ground, x forward, z up); knuckles turn about
z at the front wheel centres, wheels spin about their link y axis (positive = forward).
Every number comes from the CarDescription; inertias are those of the boxes and cylinders.
"""
from __future__ import annotations

import copy
import math
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from pieces.pose import Pose2
from vehicle.description import CarDescription, CarDescriptionError
from vehicle.modelling import CHASSIS_MU, KNUCKLE_MASS_FRACTION
from worlds.lighting import TrackLighting, write_sdf
from worlds.marks import write_sdf as write_marks
from worlds.solids import write_sdf as write_solids
from worlds.sdf_xml import SDF_VERSION, WorldError, fmt, parse_xml, sub, write_xml

TRACK_ROLES = {  # role -> RGBA of its material
    "lane": (1.0, 1.0, 1.0, 1.0),
    "edges": (0.0, 0.0, 0.0, 1.0),
    "markings": (0.0, 0.0, 0.0, 1.0),
    "hill_lane": (1.0, 1.0, 1.0, 1.0),   # the road on the hills (trackgen.export.hill_meshes)
    "hill_edges": (0.0, 0.0, 0.0, 1.0),
}
GROUND_RGBA = (0.55, 0.55, 0.55, 1.0)  # grey hall floor around the track
STEER_P_GAIN_PER_S = 100.0  # Gazebo's steering-joint position gain (not a car property)
CAMERA_CLIP_M = (0.01, 20.0)  # near/far clipping planes of the camera sensor
SURFACE_TOLERANCE_M = 1e-4  # lane mesh top vs surface_z_m (float32 STL)
_NAME_RE = re.compile(r"[A-Za-z0-9_.-]+")


# -- small builders ------------------------------------------------------------------------
def _check_name(name: str, what: str) -> None:
    if not isinstance(name, str) or not _NAME_RE.fullmatch(name):
        raise WorldError(f"{what} {name!r}: expected letters, digits, '_', '-' or '.' only")


def _pose(parent: ET.Element, x=0.0, y=0.0, z=0.0, roll=0.0, pitch=0.0, yaw=0.0) -> None:
    sub(parent, "pose", fmt(x, y, z, roll, pitch, yaw))


def _material(parent: ET.Element, rgba: tuple[float, ...]) -> None:
    mat = sub(parent, "material")
    sub(mat, "ambient", fmt(*rgba))
    sub(mat, "diffuse", fmt(*rgba))
    sub(mat, "specular", fmt(0.1, 0.1, 0.1, 1.0))


def _inertial(link: ET.Element, mass_kg: float, diag_kgm2: tuple[float, float, float],
              com=(0.0, 0.0, 0.0)) -> None:
    inertial = sub(link, "inertial")
    _pose(inertial, *com)
    sub(inertial, "mass", mass_kg)
    inertia = sub(inertial, "inertia")
    for tag, value in zip(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
                          (diag_kgm2[0], 0.0, 0.0, diag_kgm2[1], 0.0, diag_kgm2[2])):
        sub(inertia, tag, value)


def box_inertia(mass_kg: float, size_m: tuple[float, float, float]) -> tuple[float, float, float]:
    """Principal moments (kg m^2) of a solid box ``(x, y, z)`` about its centre."""
    x, y, z = size_m
    return (mass_kg * (y * y + z * z) / 12, mass_kg * (x * x + z * z) / 12,
            mass_kg * (x * x + y * y) / 12)


def wheel_inertia(mass_kg: float, radius_m: float, width_m: float) -> tuple[float, float, float]:
    """Principal moments (kg m^2) of a solid cylinder whose axis is y (a wheel)."""
    side = mass_kg * (3 * radius_m ** 2 + width_m ** 2) / 12
    return (side, mass_kg * radius_m ** 2 / 2, side)


def _static_inertial(link: ET.Element) -> None:
    """Explicit nominal inertia for static links (dartpy warns when it is missing)."""
    _inertial(link, 1.0, (1.0, 1.0, 1.0))


def _model_config(model_dir: Path, name: str, description: str) -> None:
    root = ET.Element("model")
    sub(root, "name", name)
    sub(root, "version", "1.0")
    sub(root, "sdf", "model.sdf", version=SDF_VERSION)
    author = sub(root, "author")
    sub(author, "name", "nxpcup-sim")
    sub(author, "email", "")
    sub(root, "description", description)
    write_xml(root, model_dir / "model.config")


def _mkdir(path: Path) -> None:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise WorldError(f"{path}: cannot create folder ({exc.strerror})") from None


# -- track ---------------------------------------------------------------------------------
def write_track_model(model_dir: Path, name: str, meshes: dict[str, str], *,
                      surface_z_m: float) -> None:
    """Write ``model.config`` and ``model.sdf`` of a static track model.

    ``meshes`` maps a role ("lane", "edges", "markings") to an existing mesh file path
    relative to ``model_dir`` (e.g. ``"meshes/lane.stl"``). Each role gets a visual (lane
    white, edges and markings black, plain RGBA materials) and a collision. The meshes are
    in the model frame (= world frame): the lane's top must be at ``surface_z_m``.
    """
    model_dir = Path(model_dir)
    _check_name(name, "track model name")
    if "lane" not in meshes:
        raise WorldError(f"{model_dir}: track meshes {sorted(meshes)} lack the 'lane' mesh")
    for role, rel in meshes.items():
        if role not in TRACK_ROLES:
            raise WorldError(f"{model_dir}: unknown mesh role {role!r} (expected one of "
                             f"{', '.join(TRACK_ROLES)})")
        rel_path = Path(rel)
        if rel_path.is_absolute() or ".." in rel_path.parts:
            raise WorldError(f"{model_dir}: mesh path {rel!r} must be relative and inside the model folder")
        if not (model_dir / rel_path).is_file():
            raise WorldError(f"{model_dir / rel_path}: {role} mesh file not found")
    _check_surface(model_dir / meshes["lane"], surface_z_m)

    root = ET.Element("sdf", version=SDF_VERSION)
    model = sub(root, "model", name=name)
    sub(model, "static", True)
    link = sub(model, "link", name="link")
    _static_inertial(link)
    for role, rel in meshes.items():
        uri = f"model://{name}/{Path(rel).as_posix()}"
        for kind in ("collision", "visual"):
            el = sub(link, kind, name=f"{role}_{kind}")
            mesh = sub(sub(el, "geometry"), "mesh")
            sub(mesh, "uri", uri)
            sub(mesh, "scale", "1 1 1")
            if kind == "visual":
                sub(el, "cast_shadows", False)
                _material(el, TRACK_ROLES[role])
    _mkdir(model_dir)
    write_xml(root, model_dir / "model.sdf")
    _model_config(model_dir, name, f"NXP Cup track '{name}' (generated by nxpcup-sim); "
                  f"driving surface at z = {fmt(surface_z_m)} m.")


def _check_surface(lane_path: Path, surface_z_m: float) -> None:
    from stl import mesh as stl_mesh  # numpy-stl: not trimesh, whose import (scipy) is ~0.5 s

    try:
        data = stl_mesh.Mesh.from_file(str(lane_path), calculate_normals=False)
        top_m = float(data.vectors[..., 2].max())
    except Exception as exc:  # numpy-stl raises many types for bad files
        raise WorldError(f"{lane_path}: cannot read lane mesh ({exc})") from None
    if abs(top_m - surface_z_m) > SURFACE_TOLERANCE_M:
        raise WorldError(f"{lane_path}: lane top at z = {top_m:.6f} m, expected surface_z_m = "
                         f"{surface_z_m:.6f} m")


# -- car -----------------------------------------------------------------------------------
def _steer_joint_limit_rad(car: CarDescription) -> float:
    """Inner wheel angle at the bicycle steering limit (Ackermann geometry, as Gazebo)."""
    a, wb, sep = car.steering.limit_rad, car.chassis.wheelbase_m, car.chassis.track_m
    return math.atan2(2 * wb * math.sin(a), 2 * wb * math.cos(a) - sep * math.sin(a))


def _wheel_link(model: ET.Element, car: CarDescription, name: str, x: float, y: float) -> None:
    w = car.wheels
    link = sub(model, "link", name=name)
    _pose(link, x, y, w.radius_m)
    _inertial(link, w.mass_kg, wheel_inertia(w.mass_kg, w.radius_m, w.width_m))
    for kind in ("collision", "visual"):
        el = sub(link, kind, name=f"{name}_{kind}")
        _pose(el, 0, 0, 0, math.pi / 2, 0, 0)  # cylinder axis z -> link y
        cyl = sub(sub(el, "geometry"), "cylinder")
        sub(cyl, "radius", w.radius_m)
        sub(cyl, "length", w.width_m)
        if kind == "collision":
            ode = sub(sub(sub(el, "surface"), "friction"), "ode")
            sub(ode, "mu", w.friction_mu)
            sub(ode, "mu2", w.friction_mu)
        else:
            _material(el, (0.05, 0.05, 0.05, 1.0))


def _revolute(model: ET.Element, name: str, parent: str, child: str, axis: str,
              limit_rad: float | None = None, velocity_radps: float | None = None) -> None:
    joint = sub(model, "joint", name=name, type="revolute")
    sub(joint, "parent", parent)
    sub(joint, "child", child)
    ax = sub(joint, "axis")
    sub(ax, "xyz", axis)
    if limit_rad is not None:
        lim = sub(ax, "limit")
        sub(lim, "lower", -limit_rad)
        sub(lim, "upper", limit_rad)
        if velocity_radps is not None:
            sub(lim, "velocity", velocity_radps)


def car_model_element(car: CarDescription) -> ET.Element:
    """The ``<model>`` element of the car (see the module docstring for its frames)."""
    _check_name(car.name, "car model name")
    c, w, cam = car.chassis, car.wheels, car.camera
    knuckle_kg = KNUCKLE_MASS_FRACTION * w.mass_kg
    body_kg = c.mass_kg - 4 * w.mass_kg - 2 * knuckle_kg
    if body_kg <= 0:
        raise CarDescriptionError(
            f"car {car.name!r}: chassis.mass_kg = {c.mass_kg} must exceed four wheels and two "
            f"knuckles ({4 * w.mass_kg + 2 * knuckle_kg:.4g} kg)")
    half = c.track_m / 2
    model = ET.Element("model", name=car.name)

    chassis = sub(model, "link", name="chassis")
    box = (c.length_m, c.width_m, c.height_m)
    centre = (c.length_m / 2 - c.rear_overhang_m, 0.0, c.cog_height_m)
    _inertial(chassis, body_kg, box_inertia(body_kg, box), centre)
    for kind in ("collision", "visual"):
        el = sub(chassis, kind, name=f"chassis_{kind}")
        _pose(el, *centre)
        sub(sub(sub(el, "geometry"), "box"), "size", fmt(*box))
        if kind == "collision":
            ode = sub(sub(sub(el, "surface"), "friction"), "ode")
            sub(ode, "mu", CHASSIS_MU)
            sub(ode, "mu2", CHASSIS_MU)
        else:
            _material(el, (0.1, 0.3, 0.8, 1.0))
    sensor = sub(chassis, "sensor", name="camera", type="camera")
    _pose(sensor, cam.forward_m, 0, cam.height_m, 0, cam.pitch_rad, 0)
    sub(sensor, "always_on", True)
    sub(sensor, "update_rate", cam.fps_hz)
    sub(sensor, "visualize", True)
    sub(sensor, "topic", "/camera")
    camera = sub(sensor, "camera", name="line_camera")
    sub(camera, "horizontal_fov", cam.hfov_rad)
    image = sub(camera, "image")
    sub(image, "width", cam.width_px)
    sub(image, "height", cam.height_px)
    sub(image, "format", "L8")
    clip = sub(camera, "clip")
    sub(clip, "near", CAMERA_CLIP_M[0])
    sub(clip, "far", CAMERA_CLIP_M[1])

    steer_limit = _steer_joint_limit_rad(car)
    for side, y in (("l", half), ("r", -half)):
        knuckle = sub(model, "link", name=f"knuckle_{side}")
        _pose(knuckle, c.wheelbase_m, y, w.radius_m)
        _inertial(knuckle, knuckle_kg, box_inertia(knuckle_kg, (w.width_m,) * 3))
        _revolute(model, f"steer_{side}_joint", "chassis", f"knuckle_{side}", "0 0 1",
                  steer_limit, car.steering.rate_radps)
    for name, parent, x, y in (("wheel_fl", "knuckle_l", c.wheelbase_m, half),
                               ("wheel_fr", "knuckle_r", c.wheelbase_m, -half),
                               ("wheel_rl", "chassis", 0.0, half),
                               ("wheel_rr", "chassis", 0.0, -half)):
        _wheel_link(model, car, name, x, y)
        _revolute(model, f"{name}_joint", parent, name, "0 1 0")

    ack = sub(model, "plugin", filename="gz-sim-ackermann-steering-system",
              name="gz::sim::systems::AckermannSteering")
    sub(ack, "steering_only", True)
    sub(ack, "left_steering_joint", "steer_l_joint")
    sub(ack, "right_steering_joint", "steer_r_joint")
    sub(ack, "wheel_base", c.wheelbase_m)
    sub(ack, "wheel_separation", c.track_m)
    sub(ack, "steering_limit", car.steering.limit_rad)
    sub(ack, "wheel_radius", w.radius_m)
    sub(ack, "steer_p_gain", STEER_P_GAIN_PER_S)
    sub(ack, "steer_cmd_max", car.steering.rate_radps)  # servo slew rate
    sub(ack, "steer_cmd_min", -car.steering.rate_radps)
    sub(ack, "topic", "/steer_angle")

    d = car.drive
    diff = sub(model, "plugin", filename="gz-sim-diff-drive-system",
               name="gz::sim::systems::DiffDrive")
    sub(diff, "left_joint", "wheel_rl_joint")
    sub(diff, "right_joint", "wheel_rr_joint")
    sub(diff, "wheel_separation", c.track_m)
    sub(diff, "wheel_radius", w.radius_m)
    sub(diff, "min_linear_velocity", -d.max_speed_mps)
    sub(diff, "max_linear_velocity", d.max_speed_mps)
    sub(diff, "min_linear_acceleration", -d.max_brake_mps2)
    sub(diff, "max_linear_acceleration", d.max_accel_mps2)
    sub(diff, "topic", "/cmd_vel")
    sub(diff, "odom_topic", "/diffodom")
    return model


def write_car_model(model_dir: Path, car: CarDescription) -> None:
    """Write ``model.config`` and ``model.sdf`` of the car (a Gazebo model folder)."""
    model_dir = Path(model_dir)
    root = ET.Element("sdf", version=SDF_VERSION)
    root.append(car_model_element(car))
    _mkdir(model_dir)
    write_xml(root, model_dir / "model.sdf")
    _model_config(model_dir, car.name, "NXP Cup car (Ackermann steering, rear drive, camera), "
                  "generated by nxpcup-sim from a vehicle.description.CarDescription.")


# -- world ---------------------------------------------------------------------------------
def _inline_model(world_dir: Path, name: str) -> ET.Element:
    """The ``<model>`` of ``world_dir/models/name/model.sdf`` with world-relative mesh URIs."""
    model_dir = world_dir / "models" / name
    doc = parse_xml(model_dir / "model.sdf", "model file")
    model = doc.root.find("model")
    if model is None:
        raise doc.error(doc.root, "expected a <model> element under <sdf>")
    model = copy.deepcopy(model)
    prefix = f"model://{name}/"
    for uri in model.iter("uri"):
        text = (uri.text or "").strip()
        if text.startswith(prefix):
            uri.text = Path(os.path.relpath(model_dir / text[len(prefix):], world_dir)).as_posix()
    for pose in model.findall("pose"):
        model.remove(pose)
    return model


def _ground(world: ET.Element) -> None:
    model = sub(world, "model", name="ground_plane")
    sub(model, "static", True)
    link = sub(model, "link", name="link")
    _static_inertial(link)
    for kind in ("collision", "visual"):
        el = sub(link, kind, name=kind)
        plane = sub(sub(el, "geometry"), "plane")
        sub(plane, "normal", "0 0 1")
        sub(plane, "size", "100 100")
        if kind == "visual":
            _material(el, GROUND_RGBA)


def _sun(world: ET.Element) -> None:
    light = sub(world, "light", name="sun", type="directional")
    sub(light, "cast_shadows", True)
    _pose(light, 0, 0, 10)
    sub(light, "diffuse", "0.9 0.9 0.9 1")
    sub(light, "specular", "0.2 0.2 0.2 1")
    sub(light, "direction", "-0.3 0.2 -1")


def write_world(path: Path, *, world_name: str, track_model: str, car_model: str,
                car_pose: Pose2, car_z_m: float, lighting: TrackLighting | None = None,
                barcodes: tuple = (), boxes: tuple = (), tunnels: tuple = ()) -> None:
    """Write a world with ground, sun, the track and the car standing at ``car_pose``;
    ``lighting`` other than the default adds its lamps and photometric numbers
    (:func:`worlds.lighting.write_sdf`), ``barcodes`` their cards (:func:`worlds.marks.write_sdf`),
    ``boxes`` the objects standing on the track (:func:`worlds.solids.write_sdf`), ``tunnels``
    ``(x_m, y_m, yaw_rad, length_m, width_m, clearance_m, wall_m)`` roofs and walls over the
    track (a static model Gazebo shows; their light is the lighting's shades).

    The models are read from ``path.parent / "models" / NAME / "model.sdf"`` (written by
    :func:`write_track_model` and :func:`write_car_model`) and inlined with mesh URIs
    relative to ``path`` (see the module docstring). ``car_z_m`` is the height of the car
    body frame (its wheels' contact plane), i.e. the track surface.
    """
    path = Path(path)
    _check_name(world_name, "world name")
    world_dir = path.parent
    root = ET.Element("sdf", version=SDF_VERSION)
    world = sub(root, "world", name=world_name)
    physics = sub(world, "physics", name="1ms", type="ode")
    sub(physics, "max_step_size", 0.001)
    sub(physics, "real_time_factor", 1.0)
    for filename, name in (("gz-sim-physics-system", "Physics"),
                           ("gz-sim-user-commands-system", "UserCommands"),
                           ("gz-sim-scene-broadcaster-system", "SceneBroadcaster"),
                           ("gz-sim-sensors-system", "Sensors")):
        plugin = sub(world, "plugin", filename=filename, name=f"gz::sim::systems::{name}")
        if name == "Sensors":
            sub(plugin, "render_engine", "ogre2")
    scene = sub(world, "scene")
    sub(scene, "ambient", "0.6 0.6 0.6 1")
    sub(scene, "background", "0.7 0.7 0.7 1")
    sub(scene, "shadows", False)
    _sun(world)
    if lighting is not None and not lighting.is_default():
        write_sdf(world, lighting, fmt)
    _ground(world)
    track = _inline_model(world_dir, track_model)
    track.insert(0, ET.Element("pose"))
    track[0].text = fmt(0, 0, 0, 0, 0, 0)
    world.append(track)
    write_marks(world, tuple(barcodes), fmt, car_z_m)
    write_solids(world, tuple(boxes), car_z_m)
    _tunnels(world, tuple(tunnels), car_z_m)
    car = _inline_model(world_dir, car_model)
    car.insert(0, ET.Element("pose"))
    car[0].text = fmt(car_pose.x_m, car_pose.y_m, car_z_m, 0, 0, car_pose.yaw_rad)
    world.append(car)
    write_xml(root, path)


def _tunnels(world: ET.Element, tunnels: tuple, surface_z_m: float) -> None:
    """A static model of box visuals: each tunnel's two walls and its roof."""
    if not tunnels:
        return
    model = sub(world, "model", name="tunnels")
    sub(model, "static", True)
    link = sub(model, "link", name="roofs")
    for i, (x, y, yaw, length, width, clearance, wall) in enumerate(tunnels):
        c, s = math.cos(yaw), math.sin(yaw)
        parts = [("roof", 0.0, surface_z_m + clearance + wall / 2.0, (length, width + 2 * wall, wall))]
        parts += [(f"wall_{k}", side * (width / 2.0 + wall / 2.0), surface_z_m + clearance / 2.0,
                   (length, wall, clearance)) for k, side in enumerate((1.0, -1.0))]
        for name, across, z, size in parts:
            visual = sub(link, "visual", name=f"tunnel_{i}_{name}")
            sub(visual, "pose", fmt(x - s * across, y + c * across, z, 0, 0, yaw))
            sub(sub(sub(visual, "geometry"), "box"), "size", fmt(*size))
            material = sub(visual, "material")
            sub(material, "ambient", "0.3 0.3 0.3 1")
            sub(material, "diffuse", "0.3 0.3 0.3 1")


def write_track_world(out_dir: Path, *, track_name: str, meshes: dict[str, str],
                      start_pose: Pose2, surface_z_m: float, car: CarDescription,
                      lighting: TrackLighting | None = None, barcodes: tuple = (), boxes: tuple = (),
                      tunnels: tuple = ()) -> Path:
    """Write the track model, the car model and ``out_dir/world.sdf``; return the world path.

    ``meshes`` maps role -> path relative to ``out_dir/models/<track_name>/`` (the STL files
    must already be there, e.g. ``{"lane": "meshes/lane.stl", "edges": "meshes/edges.stl"}``).
    The car stands at ``start_pose`` on the track surface (``z = surface_z_m``).
    """
    out_dir = Path(out_dir)
    if track_name == car.name:
        raise WorldError(f"{out_dir}: track name {track_name!r} equals the car model name")
    write_track_model(out_dir / "models" / track_name, track_name, meshes, surface_z_m=surface_z_m)
    write_car_model(out_dir / "models" / car.name, car)
    world_path = out_dir / "world.sdf"
    write_world(world_path, world_name=track_name, track_model=track_name, car_model=car.name,
                car_pose=start_pose, car_z_m=surface_z_m, lighting=lighting, barcodes=barcodes, boxes=boxes,
                tunnels=tunnels)
    return world_path
