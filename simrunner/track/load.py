"""The simulator's view of a track: a top-down raster, the start pose, the lap gate.

``load_track(spec)`` accepts
- a layout file (``*.txt``): built with ``trackgen`` (no preview) into a folder of the track
  cache and read from there like any trackgen folder. The cache key covers everything the
  build depends on (the layout's path and bytes, the car, the source files of ``pieces``,
  ``trackgen`` and ``worlds``, Python's version and the installed files of numpy, shapely,
  manifold3d and trimesh), so the next run of the same layout skips the build and
  trackgen's imports (trimesh, ~0.5 s). Cache folder: ``$NXPCUP_SIM_TRACK_CACHE``, else
  ``$XDG_CACHE_HOME/nxpcup-sim/tracks``, else ``~/.cache/nxpcup-sim/tracks``; the
  :data:`CACHE_KEEP` most recently used builds are kept. ``NXPCUP_SIM_TRACK_CACHE=off``, or
  a cache that cannot be written, builds into a temporary folder deleted after reading.
  A layout that fails to build is never cached (its error is raised every time);
- a trackgen output folder (holds ``world.sdf``);
- a world file (``*.sdf`` / ``*.world``);
- a Gazebo model folder (``model.config`` beside a ``*.world``, like NXP's
  ``nxp_raceway/``): its ``.world`` is used so the include pose applies;
and always reads the world through ``worlds.sdf_read.read_world`` (one path for all).

From the scene:
- ``raster``: every mesh visual's top faces painted into a ``TrackRaster`` (see raster.py).
- ``surface_z_m``: top of the lane = highest upward face of the collision meshes (else of the
  lane visuals, else of all visuals), world frame.
- ``start``: the car's pose in the world if the world places one, else track.json's
  ``start_pose``, else the world origin heading +x (NXP's worlds put the car's start there).
- ``gate`` / ``gate_half_width_m``: track.json's ``finish_gate``; without one the gate is the
  start pose and its half width the larger of the road's extents to the left and to the right
  of the start pose, measured on the raster along the start's lateral axis (so the gate
  segment spans the whole road there, edge lines included).
- ``lap_length_m``: track.json's ``length_m``; without it an estimate: road area (raster) /
  road width at the start. The estimate undercounts crossings (their area counts once but
  is driven twice), typically by a few per cent; the judge only uses it for its minimum-lap
  distance, which tolerates that (``lap_length_estimated`` is then True).
- ``centreline``: track.json's ``centreline`` ``(N, 2)`` or None.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pieces.pose import Pose2
from simrunner.errors import SimError
from simrunner.track.raster import (DEFAULT_M_PER_PX, TrackRaster, build_raster, layer_from_visual,
                              upward_triangles, world_triangles)

LAYOUT_SUFFIXES = (".txt",)
WORLD_SUFFIXES = (".sdf", ".world")
_WIDTH_SEARCH_M = 3.0  # how far to look sideways for the road's edge
CACHE_ENV = "NXPCUP_SIM_TRACK_CACHE"
CACHE_KEEP = 32  # built layouts kept in the cache (least recently used removed first)
_CACHE_FORMAT = b"nxpcup-sim track cache 1"


class TrackLoadError(SimError, ValueError):
    """The track spec cannot be read or makes no drivable track (message names the file)."""


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

    @property
    def road_mask(self) -> np.ndarray:
        """``(H, W) bool`` road pixels of ``raster``."""
        return self.raster.road_mask


# -- spec -> scene -----------------------------------------------------------------------
def load_track(spec: str | Path, *, car=None, m_per_px: float = DEFAULT_M_PER_PX) -> SimTrack:
    """Load a track from a layout file, a trackgen folder, a world file or a model folder.

    ``car`` (a ``vehicle.description.CarDescription``) is only used when a layout is built (trackgen
    checks curve radii against the car). Raises ``TrackLoadError`` (a ``SimError``) for a bad
    spec, layout or world; a layout's own error is its ``__cause__``.
    """
    path = Path(spec)
    if path.is_file() and path.suffix.lower() in LAYOUT_SUFFIXES:
        cached = _cached_build(path, car)
        if cached is not None:
            try:
                scene = _read_world(cached / "world.sdf")
            except TrackLoadError:  # a damaged cache entry: drop it, build afresh below
                shutil.rmtree(cached, ignore_errors=True)
            else:
                return track_from_scene(scene, source=path, name=None, m_per_px=m_per_px)
        from trackgen import TrackError
        from trackgen.build import build  # trackgen is only needed for layouts

        with tempfile.TemporaryDirectory(prefix="nxpcup-track-") as tmp:
            try:
                result = build(path, Path(tmp) / "track", car=car, preview=False)
            except TrackError as exc:
                raise TrackLoadError(str(exc)) from exc
            scene = _read_world(result.world_path)
            return track_from_scene(scene, source=path, name=None, m_per_px=m_per_px)
    if path.is_file() and path.suffix.lower() not in WORLD_SUFFIXES:
        raise TrackLoadError(f"{path}: not a track: expected a layout ({', '.join(LAYOUT_SUFFIXES)}), "
                             f"a world ({', '.join(WORLD_SUFFIXES)}) or a track folder")
    return track_from_scene(_read_world(path), source=path, m_per_px=m_per_px)


# -- layout build cache ------------------------------------------------------------------
def _cache_dir() -> Path | None:
    """The track cache folder (see the module docstring), None when switched off."""
    configured = os.environ.get(CACHE_ENV, "")
    if configured.lower() in ("off", "0", "no", "false"):
        return None
    if configured:
        return Path(configured)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "nxpcup-sim" / "tracks"


def _cache_key(layout: Path, car) -> str:
    """Hex digest of everything a layout's trackgen build depends on (module docstring).
    A dependency counts by its installed file (path, size, modification time): an upgrade
    rewrites it (cheaper than importlib.metadata, ~30 ms)."""
    import importlib.util
    import platform

    if car is None:
        from vehicle.description import CarDescription

        car = CarDescription()
    h = hashlib.sha256(_CACHE_FORMAT)
    for part in (str(layout.resolve()), repr(car), sys.version, platform.machine()):
        h.update(b"\0" + part.encode())
    h.update(b"\0" + layout.read_bytes())
    for dependency in ("numpy", "shapely", "manifold3d", "trimesh"):
        origin = importlib.util.find_spec(dependency).origin
        st = os.stat(origin)
        h.update(f"\0{dependency} {origin} {st.st_size} {st.st_mtime_ns}".encode())
    for package in ("pieces", "trackgen", "worlds"):
        root = Path(importlib.util.find_spec(package).origin).parent
        for f in sorted(root.rglob("*")):
            if f.is_file() and "__pycache__" not in f.parts:
                name = f"\0{package}/{f.relative_to(root).as_posix()}\0"
                h.update(name.encode() + f.read_bytes())
    return h.hexdigest()[:32]


def _cached_build(layout: Path, car) -> Path | None:
    """The cache folder holding ``trackgen build`` of ``layout`` (built now if missing), or
    None when the cache is off or unusable (the caller then builds into a temporary folder).
    Layout errors are raised as :class:`TrackLoadError`, as without the cache."""
    try:
        root = _cache_dir()
        if root is None:
            return None
        entry = root / _cache_key(layout, car)
        if (entry / "world.sdf").is_file():
            os.utime(entry)  # most recently used
            return entry
        root.mkdir(parents=True, exist_ok=True)
    except Exception:  # noqa: BLE001 - the cache never stops a run: build without it
        return None
    from trackgen import TrackError
    from trackgen.build import OutputError, build

    try:
        build(layout, entry, car=car, preview=False)  # written beside, renamed into place
    except OutputError:  # a concurrent run built it first, or the cache is not writable
        return entry if (entry / "world.sdf").is_file() else None
    except TrackError as exc:
        raise TrackLoadError(str(exc)) from exc
    _prune_cache(root)
    return entry


def _prune_cache(root: Path) -> None:
    """Remove all but the CACHE_KEEP most recently used builds, and build temporaries
    (``.NAME.*``, left only by a killed process) older than a day."""
    import time

    try:
        folders = [(p, p.stat().st_mtime) for p in root.iterdir() if p.is_dir()]
    except OSError:
        return
    builds = sorted((f for f in folders if not f[0].name.startswith(".")), key=lambda f: -f[1])
    stale = [f for f in folders if f[0].name.startswith(".") and f[1] < time.time() - 86400]
    for old, _ in builds[CACHE_KEEP:] + stale:
        shutil.rmtree(old, ignore_errors=True)


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
    try:
        layers = [layer for layer in (layer_from_visual(v) for v in scene.visuals) if layer is not None]
        surface_z = _surface_z(scene, layers) if layers else 0.0
    except ValueError as exc:  # an unreadable mesh file
        raise TrackLoadError(str(exc)) from None
    if not layers:
        raise TrackLoadError(f"{scene.source}: the world has no mesh visuals with upward faces "
                             f"(nothing to drive on)")
    raster = build_raster(layers, m_per_px=m_per_px)

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
    return SimTrack(
        name=name or meta.get("name") or _default_name(scene.source),
        source=source, raster=raster, surface_z_m=surface_z, start=start, gate=gate,
        gate_half_width_m=float(half), lap_length_m=float(lap_length),
        centreline=meta.get("centreline"), lap_length_estimated=estimated)


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


def _surface_z(scene, layers) -> float:
    tops = []
    for coll in getattr(scene, "collisions", None) or []:
        up = upward_triangles(world_triangles(coll.mesh_path, coll.world_from_mesh, coll.scale))
        if len(up):
            tops.append(float(up[:, :, 2].max()))
    if tops:
        return max(tops)
    lane = [layer.top_z_m for layer, v in zip(layers, scene.visuals) if getattr(v, "role", None) == "lane"]
    return max(lane) if lane else max(layer.top_z_m for layer in layers)


def _default_name(source: Path) -> str:
    source = Path(source)
    if source.is_dir():
        return source.name
    return source.parent.name if source.stem in ("world", "model") else source.stem


def _pose(value, where: str) -> Pose2:
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in value)):
        raise TrackLoadError(f"{where}: expected [x_m, y_m, yaw_rad], got {value!r}")
    return Pose2(*value)


def _read_track_json(path: Path) -> dict:
    """The fields of a track.json (format nxpcup-track/1) the simulator uses, checked."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except OSError as exc:
        raise TrackLoadError(f"{path}: cannot read ({exc.strerror})") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise TrackLoadError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(data, dict) or not str(data.get("format", "")).startswith("nxpcup-track/"):
        raise TrackLoadError(f"{path}: expected a JSON object with \"format\": \"nxpcup-track/1\"")
    out: dict = {}
    if isinstance(data.get("name"), str) and data["name"]:
        out["name"] = data["name"]
    if data.get("start_pose") is not None:
        out["start_pose"] = _pose(data["start_pose"], f"{path}: start_pose")
    gate = data.get("finish_gate")
    if gate is not None:
        half = gate.get("half_width_m") if isinstance(gate, dict) else None
        if not isinstance(half, (int, float)) or not half > 0:
            raise TrackLoadError(f"{path}: finish_gate: expected {{\"pose\": [x, y, yaw], "
                                 f"\"half_width_m\": > 0}}, got {gate!r}")
        out["finish_gate"] = (_pose(gate.get("pose"), f"{path}: finish_gate.pose"), float(half))
    length = data.get("length_m")
    if length is not None:
        if not isinstance(length, (int, float)) or not (length > 0 and math.isfinite(length)):
            raise TrackLoadError(f"{path}: length_m: expected a positive number, got {length!r}")
        out["length_m"] = float(length)
    centre = data.get("centreline")
    if centre is not None:
        try:
            arr = np.asarray(centre, dtype=float) if isinstance(centre, list) else None
        except (TypeError, ValueError):
            arr = None
        if arr is None or arr.ndim != 2 or arr.shape[1] != 2 or len(arr) < 2 or not np.isfinite(arr).all():
            raise TrackLoadError(f"{path}: centreline: expected a list of [x_m, y_m] points")
        arr.flags.writeable = False
        out["centreline"] = arr
    return out
