"""Footprint to mesh: shapely (2D) -> manifold3d CrossSection -> extrude -> trimesh.

Do the booleans in 2D and extrude once (see platform-facts: ~8x faster than 3D booleans,
and world-placed footprints unioned with ``shapely.union_all(..., grid_size=1e-6)`` then
extruded stay watertight).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import shapely

from .spec import PieceError, check_range

if TYPE_CHECKING:  # at run time trimesh (~0.5 s: it imports scipy) and manifold3d load in
    import trimesh  # the functions, on the first mesh, not with ``pieces``
    from manifold3d import CrossSection

def _rings(geom) -> list[np.ndarray]:
    """Every exterior and interior ring of a (Multi)Polygon as ``(N, 2)`` float arrays,
    without the closing duplicate vertex."""
    rings: list[np.ndarray] = []
    for poly in shapely.get_parts(geom):
        if poly.geom_type != "Polygon":
            raise PieceError(f"footprint part is a {poly.geom_type}: expected Polygon parts")
        if poly.is_empty:
            continue
        for ring in (poly.exterior, *poly.interiors):
            rings.append(np.asarray(ring.coords, dtype=float)[:-1, :2])
    return rings


def cross_section(geom) -> CrossSection:
    """manifold3d CrossSection of a shapely Polygon / MultiPolygon (holes kept)."""
    from manifold3d import CrossSection, FillRule

    return CrossSection(_rings(geom), FillRule.EvenOdd)


def extrude_arrays(geom, thickness_m: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`extrude_footprint` as plain arrays ``(vertices (V, 3) float64, faces (F, 3)
    int64)``, without trimesh (which costs ~0.5 s to import: scipy)."""
    thickness_m = check_range("thickness_m", thickness_m, 0.0)
    if geom is None or geom.is_empty:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    solid = cross_section(geom).extrude(thickness_m)
    mesh = solid.to_mesh64()
    verts = np.asarray(mesh.vert_properties, dtype=float)[:, :3]
    faces = np.asarray(mesh.tri_verts, dtype=np.int64)
    return verts, faces


def extrude_footprint(geom, thickness_m: float) -> trimesh.Trimesh:
    """Watertight slab mesh of a shapely Polygon/MultiPolygon, z from 0 to ``thickness_m``.

    Vertices ``(V, 3)`` float64 metres, faces ``(F, 3)`` int64, outward normals. An empty
    footprint gives an empty mesh. Raises :class:`pieces.PieceError` for a non-positive
    thickness or non-polygonal parts.
    """
    import trimesh

    verts, faces = extrude_arrays(geom, thickness_m)
    return trimesh.Trimesh(verts, faces, process=False)
