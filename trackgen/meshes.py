"""Slab meshes of a track as plain arrays: binary STL out, watertightness as a consumer sees it.

``trackgen build`` used trimesh for three small things -- hold a mesh, write binary STL,
check it is watertight after the float32 round trip -- and importing trimesh (it imports
scipy) cost ~0.5 s of every build. These are a few lines of numpy each:

* :class:`SlabMesh`: ``vertices (V, 3)`` float64 metres, ``faces (F, 3)`` int64;
* :func:`stl_bytes`: binary STL (80-byte header naming the writer, no date: the same mesh
  gives the same bytes), face normals from the float64 geometry;
* :func:`watertight_after_stl`: the vertices rounded to float32 as an STL file stores them,
  equal ones merged (as every STL reader does), then every edge must belong to exactly two
  faces that use it in opposite directions (closed and consistently wound), with no
  degenerate face. trimesh objects (``.vertices``, ``.faces``) are accepted too.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

STL_HEADER = b"nxpcup-sim trackgen binary STL".ljust(80, b" ")
_STL_DTYPE = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])


@dataclass(frozen=True, eq=False)
class SlabMesh:
    """A triangle mesh: ``vertices (V, 3)`` float64, ``faces (F, 3)`` int64 indices."""

    vertices: np.ndarray
    faces: np.ndarray

    def export(self, path: str | Path, file_type: str = "stl") -> None:
        """Write binary STL (the trimesh spelling, for callers of either)."""
        if file_type != "stl":
            raise ValueError(f"file_type={file_type!r}: only 'stl' is written")
        Path(path).write_bytes(stl_bytes(self))


def stl_bytes(mesh) -> bytes:
    """Binary STL of ``mesh`` (anything with ``vertices`` and ``faces``)."""
    tri = np.asarray(mesh.vertices, dtype=float)[np.asarray(mesh.faces, dtype=np.int64)]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)
    records = np.zeros(len(tri), dtype=_STL_DTYPE)
    records["normal"] = normal
    records["vertices"] = tri
    return STL_HEADER + np.uint32(len(tri)).tobytes() + records.tobytes()


def watertight_after_stl(mesh) -> tuple[bool, int, int]:
    """``(closed and consistently wound, faces, Euler number)`` of ``mesh`` after the float32
    STL round trip with equal vertices merged."""
    tri = np.asarray(mesh.vertices, dtype=float)[np.asarray(mesh.faces, dtype=np.int64)]
    flat = tri.astype(np.float32).reshape(-1, 3) + np.float32(0.0)   # -0.0 -> 0.0
    if flat.size == 0:
        return False, 0, 0
    # merge equal vertices: sort the float32 bit patterns (lexsort: linear memory, fast)
    bits = np.ascontiguousarray(flat).view(np.uint32)
    order = np.lexsort((bits[:, 2], bits[:, 1], bits[:, 0]))
    sorted_bits = bits[order]
    new = np.r_[True, (sorted_bits[1:] != sorted_bits[:-1]).any(axis=1)]
    index = np.empty(len(flat), dtype=np.int64)
    index[order] = np.cumsum(new) - 1
    faces = index.reshape(-1, 3)
    n_verts = int(new.sum())
    degenerate = ((faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2])
                  | (faces[:, 2] == faces[:, 0])).any()
    a = faces.ravel()
    b = np.roll(faces, -1, axis=1).ravel()            # directed edges a -> b of every face
    directed = np.sort(a * n_verts + b)
    undirected = np.sort(np.minimum(a, b) * n_verts + np.maximum(a, b))
    starts = np.flatnonzero(np.r_[True, undirected[1:] != undirected[:-1]])
    uses = np.diff(np.r_[starts, undirected.size])
    closed = bool((uses == 2).all())
    consistent = not (directed[1:] == directed[:-1]).any()
    euler = n_verts - uses.size + len(faces)
    return closed and consistent and not degenerate, len(faces), int(euler)
