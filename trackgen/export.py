"""World geometry of a chained track, its meshes and ``track.json``.

The world-placed 2D footprints of the physical pieces are unioned per role with
``shapely.union_all(..., grid_size=GRID_M)`` (a crossroads crossed twice is one physical
piece, so it is in the union once) and each role is extruded once (platform-facts: the
snapped union stays watertight after the float32 STL round trip).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cached_property
import shapely

from pieces.mesh import extrude_arrays

from .chain import Track
from .meshes import SlabMesh

GRID_M = 1e-6
"""Snapping grid of the unions (m)."""
FORMAT = "nxpcup-track/1"
MESH_ROLES = ("lane", "edges", "markings")


@dataclass(frozen=True, eq=False)
class TrackGeometry:
    """World-frame 2D footprints (shapely, metres) of a track and their slab meshes.

    ``lane``, ``edges``, ``markings`` (``None`` if no piece has a marking) are the unions
    per role, pairwise touching only; ``road`` = their union. ``thickness_m``: slab height.
    """

    lane: shapely.Geometry
    edges: shapely.Geometry
    markings: shapely.Geometry | None
    road: shapely.Geometry
    thickness_m: float

    @cached_property
    def meshes(self) -> dict[str, SlabMesh]:
        """Role -> watertight slab mesh, z in [0, thickness_m] (``markings`` only if any)."""
        out = {"lane": SlabMesh(*extrude_arrays(self.lane, self.thickness_m)),
               "edges": SlabMesh(*extrude_arrays(self.edges, self.thickness_m))}
        if self.markings is not None:
            out["markings"] = SlabMesh(*extrude_arrays(self.markings, self.thickness_m))
        return out


def _polygons_only(geom: shapely.Geometry) -> shapely.Geometry:
    """Drop points/lines a snapped boolean can leave; keep (Multi)Polygon parts."""
    if geom.geom_type in ("Polygon", "MultiPolygon"):
        return geom
    parts = [g for g in shapely.get_parts(geom) if g.geom_type == "Polygon" and not g.is_empty]
    return shapely.MultiPolygon(parts) if parts else shapely.Polygon()


def track_geometry(track: Track) -> TrackGeometry:
    """Union the world-placed footprints of ``track``'s physical pieces per role."""
    fp = track.world_footprints
    lane = _polygons_only(shapely.union_all(fp["lane"], grid_size=GRID_M))
    edges = _polygons_only(shapely.union_all(fp["edges"], grid_size=GRID_M))
    marks = [m for m in fp["marking"] if m is not None]
    markings = _polygons_only(shapely.union_all(marks, grid_size=GRID_M)) if marks else None
    road = _polygons_only(shapely.union_all(
        [lane, edges] + ([markings] if markings is not None else []), grid_size=GRID_M))
    return TrackGeometry(lane, edges, markings, road, track.layout.settings.thickness_m)


def _ring(ring) -> list[list[float]]:
    return [[float(x), float(y)] for x, y in ring.coords]


def polygon_json(geom: shapely.Geometry):
    """GeoJSON-like: a Polygon -> ``{"exterior": [[x, y], ...], "interiors": [[[x, y], ...]]}``
    (rings closed, as shapely gives them); a MultiPolygon -> a list of those."""
    if geom.geom_type == "Polygon":
        return {"exterior": _ring(geom.exterior), "interiors": [_ring(r) for r in geom.interiors]}
    return [polygon_json(g) for g in shapely.get_parts(geom)]


def _pose(p) -> list[float]:
    return [p.x_m, p.y_m, p.yaw_rad]


def track_json(track: Track, geometry: TrackGeometry) -> dict:
    """The ``track.json`` document (format ``nxpcup-track/1``, docs/DESIGN.md)."""
    layout = track.layout
    s = layout.settings
    gate = track.finish_gate()
    return {
        "format": FORMAT,
        "name": layout.name,
        "layout": layout.path,
        "settings": {"lane_width_m": s.lane_width_m, "edge_width_m": s.edge_width_m,
                     "thickness_m": s.thickness_m, "arc_tolerance_m": s.arc_tolerance_m,
                     "scale": layout.scale},
        "pieces": [{"index": p.index, "kind": p.kind.name, "line": p.line,
                    "params": dict(p.piece.params),
                    "pose": _pose(p.entry_world if p.revisit else p.world_from_piece),
                    "revisit": p.revisit} for p in track.passes],
        "start_pose": _pose(track.car_start_pose()),
        "finish_gate": None if gate is None else {"pose": _pose(gate[0]), "half_width_m": gate[1]},
        "centreline": track.centreline().tolist(),
        "course": [{"index": p.index, "kind": p.kind.name, "line": p.line, "s_start_m": a, "s_end_m": b}
                   for p, (a, b) in zip(track.passes, track.course_sections())],
        "length_m": track.length_m,
        "surface_z_m": s.thickness_m,
        "lane_polygon": polygon_json(geometry.lane),
        "road_polygon": polygon_json(geometry.road),
        **({} if track.lighting().is_default() else {"lighting": track.lighting().to_json()}),
        **({"barcodes": [b.to_json() for b in layout.barcodes]} if layout.barcodes else {}),
        **({"boxes": [b.to_json() for b in layout.boxes]} if layout.boxes else {}),
    }


def dumps_track_json(doc: dict) -> str:
    """Deterministic text of a track.json document (finite floats only)."""
    return json.dumps(doc, allow_nan=False) + "\n"
