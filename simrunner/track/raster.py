"""Top-down raster of a flat track: the picture the camera samples and the mask the judge reads.

Raster frame: a north-up image of the world's xy plane. Pixel ``(row, col)`` has its centre at
world ``x = x0 + col * m_per_px``, ``y = y0 - row * m_per_px`` where ``(x0, y0) =
origin_xy_m`` is the centre of the top-left pixel. Pixel coordinates are returned as
``(col, row)`` float pairs (OpenCV's ``(x, y)`` order, so they feed ``cv2.remap`` directly);
integer values are pixel centres.

Painting: every visual mesh contributes its upward-facing triangles (normal z > 0.5 in the
world frame) projected onto z = 0, filled with the gray of its colour. Layers are painted in
order of increasing top height, brighter before darker at equal height (so black edge lines
and markings lie on top of a white lane that they overlap). Everything else is the dark floor.
``road_mask`` is the union of all track footprints (lane, edge lines, markings).

Footprint layers (a track made in memory from ``trackgen``, :func:`layer_from_footprint`) are
triangulated as trackgen's slab meshes are: manifold3d's ``CrossSection`` (it snaps x, y to a
2**-27 m grid) and its triangulator, vertices then rounded to float32 as the binary STL
stores them. So a layout gives the same raster from memory as from its built world, pixel
for pixel (tests/test_track_loading.py). The triangulation matters: each triangle's outline
is painted too, and an inner diagonal that ends at a sharp corner can paint a pixel just
outside the footprint (shapely's constrained Delaunay triangles of the same vertices gave up
to 6 differing pixels on 40 random layouts). :func:`layer_from_polygon` (shapely's
triangles) is for any other polygon.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import cv2
import numpy as np

from simrunner.track.errors import TrackLoadError

FLOOR_GRAY = 40
WHITE_GRAY = 235
BLACK_GRAY = 15
DEFAULT_M_PER_PX = 0.005
MAX_RASTER_PX = 150_000_000  # ~300 MB (image + mask); worlds' 50 m limit gives <= 101 M at 5 mm

# Diffuse colours of Gazebo's stock materials (media/materials/scripts/gazebo.material).
GAZEBO_MATERIAL_RGB = {
    "Gazebo/White": (1.0, 1.0, 1.0),
    "Gazebo/Black": (0.0, 0.0, 0.0),
    "Gazebo/Grey": (0.7, 0.7, 0.7),
    "Gazebo/Gray": (0.7, 0.7, 0.7),
    "Gazebo/DarkGrey": (0.175, 0.175, 0.175),
    "Gazebo/DarkGray": (0.175, 0.175, 0.175),
    "Gazebo/Red": (1.0, 0.0, 0.0),
    "Gazebo/Green": (0.0, 1.0, 0.0),
    "Gazebo/Blue": (0.0, 0.0, 1.0),
    "Gazebo/Yellow": (1.0, 1.0, 0.0),
    "Gazebo/Orange": (1.0, 0.5088, 0.0468),
}
# Fallback when a visual has neither rgba nor a known material: by its role.
ROLE_GRAY = {"lane": WHITE_GRAY, "edge": BLACK_GRAY, "marking": BLACK_GRAY}
_SHIFT = 8  # fixed-point bits for cv2.fillConvexPoly (sub-pixel vertices)


@dataclass(frozen=True, eq=False)
class RasterLayer:
    """One mesh's footprint: ``triangles_xy (T, 3, 2)`` world metres, its top ``top_z_m``,
    its ``gray`` (0-255) and whether it counts as road."""

    name: str
    triangles_xy: np.ndarray
    top_z_m: float
    gray: int
    is_road: bool = True


@dataclass(frozen=True, eq=False)
class TrackRaster:
    """Top-down gray image ``image (H, W) uint8`` and ``road_mask (H, W) bool`` of a track."""

    image: np.ndarray
    road_mask: np.ndarray
    m_per_px: float
    origin_xy_m: tuple[float, float]
    floor_gray: int = FLOOR_GRAY

    @property
    def shape(self) -> tuple[int, int]:
        return self.image.shape  # type: ignore[return-value]

    @property
    def extent_m(self) -> tuple[float, float, float, float]:
        """``(x_min, x_max, y_min, y_max)`` of the pixel centres."""
        h, w = self.image.shape
        x0, y0 = self.origin_xy_m
        return x0, x0 + (w - 1) * self.m_per_px, y0 - (h - 1) * self.m_per_px, y0

    def world_to_px(self, xy_m: np.ndarray) -> np.ndarray:
        """World points ``(N, 2)`` metres -> float pixel coordinates ``(N, 2)`` as (col, row)."""
        xy = np.asarray(xy_m, dtype=float).reshape(-1, 2)
        x0, y0 = self.origin_xy_m
        return np.column_stack(((xy[:, 0] - x0) / self.m_per_px, (y0 - xy[:, 1]) / self.m_per_px))

    def px_to_world(self, px: np.ndarray) -> np.ndarray:
        """Pixel coordinates ``(N, 2)`` (col, row) -> world points ``(N, 2)`` metres."""
        p = np.asarray(px, dtype=float).reshape(-1, 2)
        x0, y0 = self.origin_xy_m
        return np.column_stack((x0 + p[:, 0] * self.m_per_px, y0 - p[:, 1] * self.m_per_px))

    def on_road(self, xy_m: np.ndarray) -> np.ndarray:
        """``(N,) bool``: is each world point on a road pixel (nearest pixel; outside = False)."""
        px = np.rint(self.world_to_px(xy_m)).astype(np.int64)
        h, w = self.road_mask.shape
        inside = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
        out = np.zeros(len(px), dtype=bool)
        out[inside] = self.road_mask[px[inside, 1], px[inside, 0]]
        return out

    def gray_at(self, xy_m: np.ndarray) -> np.ndarray:
        """``(N,) uint8`` gray of the nearest pixel of each world point (floor outside)."""
        px = np.rint(self.world_to_px(xy_m)).astype(np.int64)
        h, w = self.image.shape
        inside = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
        out = np.full(len(px), self.floor_gray, dtype=np.uint8)
        out[inside] = self.image[px[inside, 1], px[inside, 0]]
        return out


def gray_of(rgba: Sequence[float] | None, material_name: str | None, role: str | None) -> int:
    """Gray level (0-255) of a visual: rgba luminance, else a Gazebo material, else its role.

    Luminance ``L = 0.299 r + 0.587 g + 0.114 b`` maps linearly to ``BLACK_GRAY +
    L * (WHITE_GRAY - BLACK_GRAY)`` (white paper is not 255 and black tape not 0 on camera).
    Unknown colour and role give a mid gray (128).
    """
    rgb = None
    if rgba is not None:
        rgb = tuple(float(v) for v in list(rgba)[:3])
    elif material_name is not None and material_name in GAZEBO_MATERIAL_RGB:
        rgb = GAZEBO_MATERIAL_RGB[material_name]
    if rgb is None:
        return ROLE_GRAY.get(role or "", 128)
    lum = min(max(0.299 * rgb[0] + 0.587 * rgb[1] + 0.114 * rgb[2], 0.0), 1.0)
    return int(round(BLACK_GRAY + lum * (WHITE_GRAY - BLACK_GRAY)))


def world_triangles(mesh_path: Path, world_from_mesh: np.ndarray,
                    scale: Sequence[float] = (1.0, 1.0, 1.0)) -> np.ndarray:
    """All triangles of a mesh file in the world frame: ``(T, 3, 3)`` metres.

    The SDF ``<scale>`` applies in the mesh frame, before ``world_from_mesh (4, 4)``. The
    file is read by ``worlds.mesh_read.read_triangles`` (binary and ASCII STL directly,
    other formats through trimesh; bounded, a damaged file refused): its WorldError becomes
    a TrackLoadError with the same message.
    """
    from worlds.mesh_read import placed_triangles, read_triangles
    from worlds.sdf_xml import WorldError

    try:
        tris = read_triangles(mesh_path)
    except WorldError as exc:
        raise TrackLoadError(str(exc)) from None
    return placed_triangles(tris, world_from_mesh, scale)


def upward_triangles(triangles: np.ndarray, min_normal_z: float = 0.5) -> np.ndarray:
    """The triangles ``(T, 3, 3)`` whose unit normal has z > ``min_normal_z``."""
    from worlds.mesh_read import upward

    return upward(triangles, min_normal_z)


def layer_from_visual(visual, triangles: np.ndarray | None = None) -> RasterLayer | None:
    """A ``RasterLayer`` from a ``worlds.sdf_read.MeshVisual`` (None if it has no top faces);
    ``triangles``: its world-frame triangles if already read (else read here)."""
    if triangles is None:
        triangles = world_triangles(visual.mesh_path, visual.world_from_mesh, visual.scale)
    up = upward_triangles(triangles)
    if len(up) == 0:
        return None
    gray = gray_of(visual.rgba, visual.material_name, getattr(visual, "role", None))
    return RasterLayer(str(visual.name), up[:, :, :2].copy(), float(up[:, :, 2].max()), gray)


def layer_from_polygon(name: str, polygon, gray: int, *, top_z_m: float = 0.0,
                       is_road: bool = True) -> RasterLayer:
    """A ``RasterLayer`` from a shapely (Multi)Polygon in world metres (holes respected)."""
    import shapely

    tris = shapely.constrained_delaunay_triangles(polygon)
    coords = [np.asarray(t.exterior.coords)[:3] for t in tris.geoms]
    arr = np.asarray(coords, dtype=float).reshape(-1, 3, 2)
    return RasterLayer(name, arr, float(top_z_m), int(gray), is_road)


def layer_from_footprint(name: str, footprint, gray: int, *, top_z_m: float = 0.0,
                         is_road: bool = True) -> RasterLayer:
    """A ``RasterLayer`` of a trackgen footprint (shapely (Multi)Polygon, world metres) with
    the top triangles of its slab mesh as ``trackgen build`` writes it, without making the
    mesh: ``pieces.mesh.cross_section`` and ``manifold3d.triangulate`` (~5 ms to import, no
    trimesh), vertices as float32 (module docstring). An empty footprint has no triangles."""
    import manifold3d

    from pieces.mesh import cross_section

    rings = [np.asarray(r, dtype=float) for r in cross_section(footprint).to_polygons() if len(r)]
    if not rings:
        return RasterLayer(name, np.zeros((0, 3, 2)), float(top_z_m), int(gray), is_road)
    index = np.asarray(manifold3d.triangulate(rings), dtype=np.int64).reshape(-1, 3)
    verts = np.vstack(rings).astype(np.float32).astype(float)  # as the binary STL stores them
    return RasterLayer(name, verts[index], float(top_z_m), int(gray), is_road)


def check_m_per_px(m_per_px: float, where: str = "") -> float:
    """``m_per_px`` as a float if it is a positive finite number, else TrackLoadError
    (prefixed with ``where``, e.g. the track's file)."""
    if (isinstance(m_per_px, bool) or not isinstance(m_per_px, (int, float, np.floating))
            or not 0 < m_per_px < math.inf):
        prefix = f"{where}: " if where else ""
        raise TrackLoadError(f"{prefix}m_per_px = {m_per_px!r}: expected a positive number of "
                             f"metres per pixel")
    return float(m_per_px)


def build_raster(layers: Iterable[RasterLayer], *, m_per_px: float = DEFAULT_M_PER_PX,
                 margin_m: float = 0.1, floor_gray: int = FLOOR_GRAY) -> TrackRaster:
    """Paint layers into a raster covering their footprints plus ``margin_m``."""
    layers = [layer for layer in layers if len(layer.triangles_xy)]
    check_m_per_px(m_per_px)
    if not layers:
        raise TrackLoadError("build_raster: no layer has upward-facing triangles (nothing to "
                             "rasterise)")
    allxy = np.concatenate([layer.triangles_xy.reshape(-1, 2) for layer in layers])
    if not np.isfinite(allxy).all():
        raise TrackLoadError("build_raster: a layer has non-finite coordinates")
    lo = allxy.min(axis=0) - margin_m
    hi = allxy.max(axis=0) + margin_m
    # Snap the origin to the pixel grid so the same track gives the same raster wherever it
    # is loaded from.
    x0 = math.floor(lo[0] / m_per_px) * m_per_px
    y0 = math.ceil(hi[1] / m_per_px) * m_per_px
    w = int(math.ceil((hi[0] - x0) / m_per_px)) + 1
    h = int(math.ceil((y0 - lo[1]) / m_per_px)) + 1
    if w * h > MAX_RASTER_PX:
        raise TrackLoadError(f"build_raster: the track spans {hi[0] - lo[0]:.4g} m x {hi[1] - lo[1]:.4g} m: "
                             f"{w} x {h} pixels at {m_per_px:g} m per pixel, more than "
                             f"{MAX_RASTER_PX:,} (use a larger m_per_px)")
    image = np.full((h, w), floor_gray, dtype=np.uint8)
    road = np.zeros((h, w), dtype=np.uint8)
    road_mask = road.view(bool)
    raster = TrackRaster(image, road_mask, float(m_per_px), (float(x0), float(y0)), floor_gray)
    order = sorted(range(len(layers)), key=lambda i: (layers[i].top_z_m, -layers[i].gray, i))
    for i in order:
        layer = layers[i]
        px = raster.world_to_px(layer.triangles_xy.reshape(-1, 2)).reshape(-1, 3, 2)
        fixed = np.rint(px * (1 << _SHIFT)).astype(np.int32)
        for tri in fixed:
            cv2.fillConvexPoly(image, tri, int(layer.gray), lineType=cv2.LINE_8, shift=_SHIFT)
            if layer.is_road:
                cv2.fillConvexPoly(road, tri, 1, lineType=cv2.LINE_8, shift=_SHIFT)
    image.flags.writeable = False
    road_mask.flags.writeable = False
    return raster
