"""The immutable piece value: footprints, centreline, ports; meshes built on first use."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import TYPE_CHECKING, Mapping

import numpy as np
import shapely

from .mesh import extrude_footprint
from .pose import Pose2
from .spec import PieceType, TrackSettings

if TYPE_CHECKING:
    import trimesh


def frozen_array(points) -> np.ndarray:
    """A read-only float64 copy, shape ``(N, 2)``."""
    arr = np.array(points, dtype=float).reshape(-1, 2)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Piece:
    """One track piece in its local frame (entry port = identity pose).

    Attributes (all metres / radians, local frame):
      kind: the :class:`PieceType`.
      settings: the :class:`TrackSettings` it was built with.
      params: read-only mapping of the resolved constructor keywords, internal units
        (e.g. ``{"radius_m": 0.8, "angle_rad": 0.785...}``).
      lane, edges, marking: shapely footprints of the white lane, the black edge lines and
        the black marking (``None`` if the piece has none). Pairwise disjoint (touching only).
      centreline: ``(N, 2)`` read-only, from the entry to the exit port (crossroads: the
        main road); ``side_centreline`` is the crossroads' side road (side_in -> side_out),
        else ``None``.
      ports: read-only mapping name -> :class:`Pose2`, heading in the direction of travel:
        ``"entry"`` (identity), ``"exit"``; crossroads also ``"side_in"``, ``"side_out"``.
      length_m: driving length of the centreline entry -> exit.
      min_radius_m: tightest centreline radius (``math.inf`` for straight pieces); for a WAVE
        the tightest radius of the smoothest path through its lane (:func:`pieces.library.wave`).
    Equality and hash follow (kind, settings, params): a piece is a function of them.
    """

    kind: PieceType
    settings: TrackSettings
    params: Mapping[str, float]
    lane: shapely.Geometry
    edges: shapely.Geometry
    marking: shapely.Geometry | None
    centreline: np.ndarray
    ports: Mapping[str, Pose2]
    length_m: float
    min_radius_m: float = math.inf
    side_centreline: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))
        object.__setattr__(self, "ports", MappingProxyType(dict(self.ports)))
        object.__setattr__(self, "centreline", frozen_array(self.centreline))
        if self.side_centreline is not None:
            object.__setattr__(self, "side_centreline", frozen_array(self.side_centreline))

    def _key(self) -> tuple:
        return (self.kind, self.settings, tuple(sorted(self.params.items())))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Piece) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v:.6g}" for k, v in self.params.items())
        return f"Piece({self.kind.name}, {args})"

    @property
    def entry(self) -> Pose2:
        return self.ports["entry"]

    @property
    def exit(self) -> Pose2:
        return self.ports["exit"]

    @cached_property
    def footprint(self) -> shapely.Geometry:
        """Union of lane, edges and marking (the whole road surface)."""
        parts = [self.lane, self.edges] + ([self.marking] if self.marking is not None else [])
        return shapely.union_all(parts)

    @cached_property
    def lane_mesh(self) -> trimesh.Trimesh:
        """White lane slab, z in [0, thickness_m]; watertight."""
        return extrude_footprint(self.lane, self.settings.thickness_m)

    @cached_property
    def edge_mesh(self) -> trimesh.Trimesh:
        """Black edge-line slab, z in [0, thickness_m]; watertight."""
        return extrude_footprint(self.edges, self.settings.thickness_m)

    @cached_property
    def marking_mesh(self) -> trimesh.Trimesh | None:
        """Marking slab or ``None`` when the piece has no marking."""
        if self.marking is None:
            return None
        return extrude_footprint(self.marking, self.settings.thickness_m)
