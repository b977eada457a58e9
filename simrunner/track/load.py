"""The simulator's view of a track: a top-down raster, the start pose, the lap gate.

``load_track(spec)`` accepts
- a layout file (``*.txt``): parsed, chained and checked by ``trackgen`` in memory (the
  checks of ``trackgen build`` but the mesh check, which concerns files the simulator does
  not use; a layout ``trackgen build`` refuses raises the same one-line message) and turned
  into a ``SimTrack`` by :func:`track_from_trackgen`: the raster is painted from the track's
  polygons; no file is written or read, no mesh is made and trimesh is not imported
  (manifold3d is, for its triangulator). It equals ``load_track`` of the layout's
  ``trackgen build`` folder, raster pixel for pixel (raster.py, "Footprint layers"; pinned
  by tests/test_track_loading.py);
- a trackgen output folder (holds ``world.sdf``);
- a world file (``*.sdf`` / ``*.world``);
- a Gazebo model folder (``model.config`` beside a ``*.world``, like NXP's
  ``nxp_raceway/``): its ``.world`` is used so the include pose applies;
and reads every world through ``worlds.sdf_read.read_world`` (one path for all worlds),
then :func:`track_from_scene`.

From a scene (a world):
- ``raster``: every mesh visual's top faces painted into a ``TrackRaster`` (see raster.py).
- ``surface_z_m``: top of the lane = highest upward face of the collision meshes (else of the
  lane visuals, else of all visuals), world frame.
- ``start``: the car's pose in the world if the world places one, else track.json's
  ``start_pose``, else the world origin heading +x (NXP's worlds put the car's start there).
- ``gate`` / ``gate_half_width_m``: track.json's ``finish_gate``; without one the gate is the
  start pose and its half width the larger of the road's extents to the left and to the right
  of the start pose, measured on the raster along the start's lateral axis (so the gate
  segment spans the whole road there, edge lines included).
- ``lap_length_m``: track.json's ``length_m``; without it the length of the traced course
  (below), else an estimate: road area (raster) / road width at the start, which
  undercounts crossings (their area counts once but is driven twice); the judge only uses it
  for its minimum-lap distance, which tolerates that (``lap_length_estimated`` is then True).
- ``centreline``: track.json's ``centreline`` ``(N, 2)`` or None.
- ``course`` (:mod:`simrunner.track.course`): the centreline with track.json's ``course``
  (the pieces along it); without a centreline the road's middle traced from the finish line
  around the loop; None when it cannot be traced.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pieces.pose import Pose2
from worlds.lighting import TrackLighting
from worlds.terrain import Terrain
from simrunner.track.course import Course, course_from_sections, traced_course
from simrunner.track.errors import TrackLoadError
from simrunner.track.raster import (DEFAULT_M_PER_PX, ROLE_GRAY, TrackRaster, build_raster,
                                    check_m_per_px, layer_from_footprint, layer_from_polygon, layer_from_visual,
                                    upward_triangles)

if TYPE_CHECKING:  # trackgen (shapely) loads only for a layout
    from trackgen.chain import Track
    from trackgen.export import TrackGeometry
    from vehicle.description import CarDescription

LAYOUT_SUFFIXES = (".txt",)
WORLD_SUFFIXES = (".sdf", ".world")
_WIDTH_SEARCH_M = 3.0  # how far to look sideways for the road's edge
_HILL_EDGE_TOL_M = 1e-4  # a road vertex this close outside a hill's side counts as on it

__all__ = ["LAYOUT_SUFFIXES", "WORLD_SUFFIXES", "SimTrack", "TrackLoadError", "load_track",
           "road_extents_m", "track_from_scene", "track_from_trackgen"]


@dataclass(frozen=True, eq=False)
class SimTrack:
    """Everything the simulator knows about a track (immutable; arrays read-only)."""

    name: str
    source: Path
    raster: TrackRaster
    surface_z_m: float
    start: Pose2
    gate: Pose2
    gate_half_width_m: float
    lap_length_m: float
    centreline: np.ndarray | None = None  # (N, 2) metres, closed loop in driving order
    lap_length_estimated: bool = False
    judged: bool = True  # False: a free floor (simrunner.track.floor), no laps, no off-track
    lighting: TrackLighting = field(default_factory=TrackLighting)  # the physical camera's light
    barcodes: tuple = ()  # printed barcodes (worlds.marks.Barcode), painted into the raster
    course: Course | None = None  # what a lap must follow (simrunner.track.course)
    boxes: tuple = ()  # objects standing on the track from the start (worlds.solids.Solid)
    terrain: Terrain = field(default_factory=Terrain)  # the hills (worlds.terrain; empty: flat)

    @property
    def road_mask(self) -> np.ndarray:
        """``(H, W) bool`` road pixels of ``raster``."""
        return self.raster.road_mask


# -- spec -> SimTrack --------------------------------------------------------------------
def load_track(spec: str | Path, *, car: CarDescription | None = None,
               m_per_px: float = DEFAULT_M_PER_PX) -> SimTrack:
    """Load a track from a layout file, a trackgen folder, a world file or a model folder.

    ``car`` (a ``vehicle.description.CarDescription``) is only used for a layout (trackgen
    checks curve radii against the car). Raises ``TrackLoadError`` (a ``SimError``) for a bad
    spec, layout or world; a layout's own error is its ``__cause__``.
    """
    path = Path(spec)
    check_m_per_px(m_per_px, str(path))
    if path.is_file() and path.suffix.lower() in LAYOUT_SUFFIXES:
        return _track_from_layout(path, car, m_per_px)
    if path.is_file() and path.suffix.lower() not in WORLD_SUFFIXES:
        raise TrackLoadError(f"{path}: not a track: expected a layout ({', '.join(LAYOUT_SUFFIXES)}), "
                             f"a world ({', '.join(WORLD_SUFFIXES)}) or a track folder")
    return track_from_scene(_read_world(path), source=path, m_per_px=m_per_px)


def _track_from_layout(path: Path, car: CarDescription | None, m_per_px: float) -> SimTrack:
    """Parse, chain and check a layout as ``trackgen build`` does, without its mesh check
    (trackgen's own, on files the simulator does not use), then :func:`track_from_trackgen`."""
    from trackgen import TrackError, load_layout  # trackgen (shapely) is only needed for layouts
    from trackgen.build import check_buildable

    try:
        checked = check_buildable(load_layout(path), car, meshes=False)
    except TrackError as exc:
        raise TrackLoadError(str(exc)) from exc
    return track_from_trackgen(checked.track, geometry=checked.geometry, source=path,
                               m_per_px=m_per_px)


# -- trackgen.Track -> SimTrack (in memory) ------------------------------------------------
def track_from_trackgen(track: Track, *, geometry: TrackGeometry | None = None,
                        source: str | Path | None = None, name: str | None = None,
                        m_per_px: float = DEFAULT_M_PER_PX) -> SimTrack:
    """A ``SimTrack`` made in memory from a chained ``trackgen.Track``: no file is written or
    read, no mesh is made (trimesh is not imported; manifold3d only for its triangulator).

    ``geometry``: the track's ``trackgen.export.TrackGeometry`` if already computed (else
    ``track_geometry(track)``). ``source`` defaults to the layout's path, ``name`` to the
    layout's name. The result equals ``load_track`` of the track's ``trackgen build`` folder
    (tests/test_track_loading.py):
    - ``raster``: the lane (white), edge-line and marking (black) footprints painted by
      :func:`~simrunner.track.raster.layer_from_footprint`: the built meshes' raster, pixel
      for pixel;
    - ``surface_z_m``: the slab thickness as the meshes' top stores it (float32);
    - ``start``, ``gate`` / ``gate_half_width_m``, ``lap_length_m``, ``centreline``: the
      values track.json holds (``Track.car_start_pose``, ``finish_gate`` -- without a
      START_FINISH the gate is the start pose and its half width is measured on the raster,
      as for a world without one -- ``length_m``, ``centreline``; see
      ``trackgen.export.track_json``). The built world's car pose is the same start, its yaw
      read back through a rotation matrix.
    The track is taken as it is (``trackgen.build.check_buildable`` checks one); raises
    ``TrackLoadError`` when the start pose is not on the road.
    """
    from trackgen.export import track_geometry

    geometry = geometry if geometry is not None else track_geometry(track)
    layout = track.layout
    source = Path(source if source is not None else layout.path)
    top_z = float(np.float32(geometry.thickness_m))  # the meshes' top as the binary STL stores it
    gray = {"lane": ROLE_GRAY["lane"], "edges": ROLE_GRAY["edge"], "markings": ROLE_GRAY["marking"],
            "hill_lane": ROLE_GRAY["lane"], "hill_edges": ROLE_GRAY["edge"]}
    layers = [layer_from_footprint(role, fp, gray[role], top_z_m=top_z)
              for role, fp in geometry.role_footprints.items()]
    raster = build_raster(layers + mark_layers(layout.barcodes, top_z, m_per_px), m_per_px=m_per_px)
    start = track.car_start_pose()
    if not bool(raster.on_road([[start.x_m, start.y_m]])[0]):
        raise TrackLoadError(f"{layout.path}: the start pose ({start.x_m:.3f}, {start.y_m:.3f}) m "
                             f"(trackgen's start pose) is not on the track")
    finish = track.finish_gate()
    if finish is not None:
        gate, half = finish
    else:
        gate, half = start, max(road_extents_m(raster, start))
    centreline = np.asarray(track.centreline(), dtype=float)
    centreline.flags.writeable = False
    course = course_from_sections(centreline, [(p.index, p.kind.name, p.line, a, b) for p, (a, b)
                                               in zip(track.passes, track.course_sections())], gate)
    return SimTrack(
        name=name or layout.name, source=source, raster=raster, surface_z_m=top_z, start=start,
        gate=gate, gate_half_width_m=float(half), lap_length_m=float(track.length_m),
        centreline=centreline, lap_length_estimated=False, lighting=track.lighting(),
        barcodes=layout.barcodes, course=course, boxes=layout.boxes, terrain=track.terrain())


def _read_world(path: Path):
    from worlds import WorldError
    from worlds.sdf_read import read_world

    try:
        return read_world(path)
    except WorldError as exc:
        raise TrackLoadError(str(exc)) from None


# -- scene -> SimTrack -------------------------------------------------------------------
def track_from_scene(scene, *, source: Path | None = None, name: str | None = None,
                     m_per_px: float = DEFAULT_M_PER_PX) -> SimTrack:
    """Build a ``SimTrack`` from a ``worlds.sdf_read.Scene`` (see the module docstring)."""
    source = Path(source if source is not None else scene.source)
    meta = _read_track_json(scene.track_json) if scene.track_json is not None else {}
    tris = _scene_triangles(scene)
    terrain = meta.get("hills", Terrain())
    layers = [layer for layer in (layer_from_visual(v, t) for v, t in zip(scene.visuals, tris.visuals))
              if layer is not None]
    if terrain:  # the road's edge vertices on a hill are on it, whatever their rounding
        terrain = terrain.widened(_HILL_EDGE_TOL_M)
        layers = [_off_hills(layer, t, terrain) for layer, t in zip(layers, tris.visuals)]
    surface_z = _surface_z(scene, layers, tris.collisions, terrain) if layers else 0.0
    if not layers:
        raise TrackLoadError(f"{scene.source}: the world has no mesh visuals with upward faces "
                             f"(nothing to drive on)")
    raster = build_raster(layers + mark_layers(scene.barcodes, surface_z, m_per_px), m_per_px=m_per_px)

    if scene.car_pose is not None:
        start, origin = scene.car_pose, "the car's pose in the world"
    elif "start_pose" in meta:
        start, origin = meta["start_pose"], "track.json's start_pose"
    else:
        start, origin = Pose2(), "no car in the world and no track.json: the world origin"
    if not bool(raster.on_road([[start.x_m, start.y_m]])[0]):
        raise TrackLoadError(f"{scene.source}: the start pose ({start.x_m:.3f}, {start.y_m:.3f}) m "
                             f"({origin}) is not on the track")
    gate_meta = meta.get("finish_gate")
    if gate_meta is not None:
        gate, half = gate_meta
    else:
        gate = start
        left, right = road_extents_m(raster, start)
        half = max(left, right)
    if "length_m" in meta:
        lap_length, estimated = meta["length_m"], False
    else:
        left, right = road_extents_m(raster, start)
        area = float(np.count_nonzero(raster.road_mask)) * raster.m_per_px ** 2
        lap_length, estimated = area / (left + right), True
    centreline = meta.get("centreline")
    if centreline is not None:
        course = course_from_sections(centreline, meta.get("course", ()), gate)
    else:
        course = traced_course(raster, gate, sum(road_extents_m(raster, gate)), lap_length)
        if course is not None and estimated:  # track.json's length_m, when given, comes first
            lap_length = course.length_m
    return SimTrack(
        name=name or meta.get("name") or _default_name(scene.source),
        source=source, raster=raster, surface_z_m=surface_z, start=start, gate=gate,
        gate_half_width_m=float(half), lap_length_m=float(lap_length),
        centreline=meta.get("centreline"), lap_length_estimated=estimated,
        lighting=scene.lighting if scene.lighting is not None else TrackLighting(),
        barcodes=scene.barcodes, course=course, boxes=scene.boxes, terrain=meta.get("hills", Terrain()))


def mark_layers(barcodes, surface_z_m: float, m_per_px: float) -> list:
    """Raster layers of printed barcodes (worlds.marks): each white card, then its black bars,
    just above the track's top so they are painted over it; not road. The painter fills a
    polygon's outline pixels too (one pixel wider than the polygon), so each bar is drawn half a
    pixel narrower on each side: bars and gaps keep their widths (the code's narrow and wide)."""
    layers = []
    top = surface_z_m + 1e-4
    inset = m_per_px / 2.0
    for i, b in enumerate(barcodes):
        layers.append(layer_from_polygon(f"barcode_{i}_card", b.card(), ROLE_GRAY["lane"], top_z_m=top,
                                         is_road=False))
        bars = [bar.buffer(-inset, join_style="mitre") for bar in b.bars()]
        layers += [layer_from_polygon(f"barcode_{i}_bar_{j}", bar, ROLE_GRAY["marking"], top_z_m=top,
                                      is_road=False) for j, bar in enumerate(bars) if not bar.is_empty]
    return layers


def road_extents_m(raster: TrackRaster, pose: Pose2) -> tuple[float, float]:
    """Distances (m) from ``pose`` to the road's edge along its left (+y) and right (-y) axis:
    the first off-road sample (half-pixel steps) minus half a step. 0 if ``pose`` is off-road."""
    step = raster.m_per_px / 2.0
    offsets = np.arange(0.0, _WIDTH_SEARCH_M, step)
    out = []
    for sign in (1.0, -1.0):
        pts = pose.apply(np.column_stack((np.zeros_like(offsets), sign * offsets)))
        on = raster.on_road(pts)
        off = np.flatnonzero(~on)
        out.append(_WIDTH_SEARCH_M if len(off) == 0 else max(float(offsets[off[0]]) - step / 2, 0.0))
    return out[0], out[1]


def _scene_triangles(scene):
    """``worlds.mesh_read.scene_triangles`` (every mesh read once, the world's limits
    checked: the same errors as ``trackgen validate``) with TrackLoadError."""
    from worlds import WorldError
    from worlds.mesh_read import scene_triangles

    try:
        return scene_triangles(scene)
    except WorldError as exc:
        raise TrackLoadError(str(exc)) from None


def _off_hills_top(triangles: np.ndarray, terrain: Terrain) -> float:
    """The highest vertex of ``triangles`` ``(T, 3, 3)`` where the ground is flat (the road on a
    hill is lifted by the hill; its ends stand on the floor), else the highest with the hill's
    lift taken off."""
    pts = triangles.reshape(-1, 3)
    lift = terrain.height_m(pts[:, 0], pts[:, 1])
    flat = lift < 1e-9
    return float(pts[flat, 2].max()) if flat.any() else float((pts[:, 2] - lift).max())


def _off_hills(layer, triangles: np.ndarray, terrain: Terrain):
    """``layer`` with its top measured off the hills (:func:`_off_hills_top`): the road on a hill
    paints in the same order as the flat road (the raster equals the layout's)."""
    from dataclasses import replace

    return replace(layer, top_z_m=_off_hills_top(upward_triangles(triangles), terrain))


def _surface_z(scene, layers, collision_triangles, terrain: Terrain = Terrain()) -> float:
    tops = []
    for tris in collision_triangles:
        up = upward_triangles(tris)
        if len(up):
            tops.append(_off_hills_top(up, terrain) if terrain else float(up[:, :, 2].max()))
    if tops:
        return max(tops)
    lane = [layer.top_z_m for layer, v in zip(layers, scene.visuals) if getattr(v, "role", None) == "lane"]
    return max(lane) if lane else max(layer.top_z_m for layer in layers)


def _default_name(source: Path) -> str:
    source = Path(source)
    if source.is_dir():
        return source.name
    return source.parent.name if source.stem in ("world", "model") else source.stem


def _read_track_json(path: Path) -> dict:
    """The fields of a track.json the simulator uses, checked: ``worlds.track_json`` (the
    reader ``trackgen validate`` uses too), its WorldError as TrackLoadError."""
    from worlds import WorldError
    from worlds.track_json import read_track_json

    try:
        return read_track_json(path)
    except WorldError as exc:
        raise TrackLoadError(str(exc)) from None
