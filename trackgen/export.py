"""World geometry of a chained track, its meshes and ``track.json``.

The world-placed 2D footprints of the physical pieces are unioned per role with
``shapely.union_all(..., grid_size=GRID_M)`` (a crossroads crossed twice is one physical
piece, so it is in the union once) and each role is extruded once (platform-facts: the
snapped union stays watertight after the float32 STL round trip).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import cached_property
import numpy as np
import shapely

from pieces.mesh import extrude_arrays
from worlds.terrain import Terrain

from .chain import Track
from .meshes import SlabMesh

GRID_M = 1e-6
"""Snapping grid of the unions (m)."""
FORMAT = "nxpcup-track/1"
MESH_ROLES = ("lane", "edges", "markings")
HILL_ROLES = {"hill_lane": "lane", "hill_edges": "edges"}
"""The meshes of the road on the hills (the lifted part of each role: :func:`hill_meshes`)."""
HILL_MESH_STEP_M = 0.02
"""Longest edge of a hill's mesh (m): the lifted surface's chord sags < 0.1 mm between vertices."""
MAX_HILL_VERTICES = 250_000
"""A hill's mesh is refined to at most about this many vertices: on a larger hill (a layout's
``@scale`` blows one up) the edges get longer than ``HILL_MESH_STEP_M`` (the kit's 1.44 m hill
takes ~4,400 vertices; at @scale = 100 the fixed step took 23 GB)."""
HILL_VERTICES_AREA, HILL_VERTICES_EDGE = 2.1, 3.0
"""A plate refined to edges of length ``x`` has about ``2.1 area / x^2 + 3.0 perimeter / x``
vertices (fitted to the kit hill's two plates: 4,366 and 1,164 vertices at 0.02 m)."""
HILL_MARGIN_M = 0.01
"""A hill's cut reaches this far beyond the road on both sides (m), so the road's edges fall inside."""


@dataclass(frozen=True, eq=False)
class TrackGeometry:
    """World-frame 2D footprints (shapely, metres) of a track and their slab meshes.

    ``lane``, ``edges``, ``markings`` (``None`` if no piece has a marking) are the unions
    per role, pairwise touching only; ``road`` = their union. ``thickness_m``: slab height.
    ``terrain``: the track's hills (:class:`worlds.terrain.Terrain`; empty: a flat track).
    """

    lane: shapely.Geometry
    edges: shapely.Geometry
    markings: shapely.Geometry | None
    road: shapely.Geometry
    thickness_m: float
    terrain: Terrain = Terrain()

    @cached_property
    def role_footprints(self) -> dict[str, shapely.Geometry]:
        """Mesh role -> its 2D footprint: ``lane``, ``edges``, ``markings`` (only if any); with
        hills, ``lane`` and ``edges`` are the flat parts and ``hill_lane``, ``hill_edges`` the
        parts on the hills (inside each hill's footprint widened by ``HILL_MARGIN_M``)."""
        if not self.terrain:
            out = {"lane": self.lane, "edges": self.edges}
        else:
            cut = _hill_cut(self.terrain)
            out = {"lane": _polygons_only(shapely.difference(self.lane, cut, grid_size=GRID_M)),
                   "edges": _polygons_only(shapely.difference(self.edges, cut, grid_size=GRID_M))}
        if self.markings is not None:
            out["markings"] = self.markings
        if self.terrain:
            for role, base in HILL_ROLES.items():
                part = _polygons_only(shapely.intersection(getattr(self, base), cut, grid_size=GRID_M))
                if not part.is_empty:
                    out[role] = part
        return out

    @cached_property
    def meshes(self) -> dict[str, SlabMesh]:
        """Role -> watertight slab mesh of :attr:`role_footprints`, z in [0, thickness_m]; the
        ``hill_*`` roles lifted onto the hills (:func:`hill_mesh`)."""
        return {role: (hill_mesh(fp, self.thickness_m, self.terrain) if role in HILL_ROLES
                       else SlabMesh(*extrude_arrays(fp, self.thickness_m)))
                for role, fp in self.role_footprints.items()}


def _hill_cut(terrain: Terrain) -> shapely.Geometry:
    """The footprints of the hills, ``HILL_MARGIN_M`` wider on both sides."""
    return shapely.union_all([shapely.Polygon(h.corners_xy()) for h in terrain.widened(HILL_MARGIN_M).hills],
                             grid_size=GRID_M)


def hill_mesh(footprint: shapely.Geometry, thickness_m: float, terrain: Terrain) -> SlabMesh:
    """The road on the hills: ``footprint`` extruded, its edges split to ``HILL_MESH_STEP_M``
    (manifold3d ``refine_to_length``) and every vertex lifted by the hill's height there
    (``warp_batch``): a plate bent over the hill, watertight on its own (a file of its own: a
    boolean union with the flat part would leave coincident vertices where the two meet)."""
    from pieces.mesh import cross_section

    wide = terrain.widened(HILL_MARGIN_M)

    def lift(v):
        v = np.array(v, dtype=float)
        v[:, 2] += wide.height_m(v[:, 0], v[:, 1])
        return v

    step = max(HILL_MESH_STEP_M, _hill_step_m(footprint.area, footprint.length))
    solid = cross_section(footprint).extrude(thickness_m).refine_to_length(step)
    mesh = solid.warp_batch(lift).to_mesh64()
    return SlabMesh(np.asarray(mesh.vert_properties, dtype=float)[:, :3], np.asarray(mesh.tri_verts, dtype=np.int64))


def _hill_step_m(area_m2: float, perimeter_m: float) -> float:
    """The edge length that refines a plate of ``area_m2`` and ``perimeter_m`` to about
    ``MAX_HILL_VERTICES`` vertices (the positive root of ``a A u^2 + b P u = N``, ``u = 1 / x``)."""
    a, b, n = HILL_VERTICES_AREA * area_m2, HILL_VERTICES_EDGE * perimeter_m, MAX_HILL_VERTICES
    u = (-b + math.sqrt(b * b + 4.0 * a * n)) / (2.0 * a) if a > 0 else n / max(b, 1e-12)
    return 1.0 / u


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
    return TrackGeometry(lane, edges, markings, road, track.layout.settings.thickness_m, track.terrain())


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
        **({"hills": [h.to_json() for h in geometry.terrain.hills]} if geometry.terrain else {}),
    }


def dumps_track_json(doc: dict) -> str:
    """Deterministic text of a track.json document (finite floats only)."""
    return json.dumps(doc, allow_nan=False) + "\n"
