"""Chaining: place every piece of a layout in the world by exact pose algebra.

The first piece's entry is the world origin heading +x. The next piece's world pose is
``world_exit_of_previous @ next.ports["entry"].inverse()`` (DESIGN.md, Conventions).

Crossroads crossed twice (the thesis's figure 8): when a CROSSROADS entry would place a
new crossroads whose centre is closer to an existing crossroads' centre than the two would
be end to end (``(C1 + C2) / 2``), it is a *re-entry* of that one physical piece: the
current pose is matched against the existing crossroads' side ports ``side_in`` (travel
towards its +y) and ``side_out.reversed()`` (towards its -y), the chain continues from the
opposite side port (``side_out`` or ``side_in.reversed()``), no second piece is created and
the match error is recorded (checked by :mod:`trackgen.validate`).
"""
from __future__ import annotations

import dataclasses

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import shapely
from shapely import affinity

from pieces.library import make_piece
from pieces.piece import Piece
from pieces.pose import Pose2
from pieces.spec import PieceError, PieceType

from .layout import Layout, LayoutEntry

START_BEFORE_FINISH_M = 0.3
"""With a START_FINISH piece the car starts this far before the centre of its marking."""
MAX_TRACK_VERTICES = 500_000
"""Most centreline samples in one layout (every pass counted): bounds the memory and time of
the footprints, unions and meshes (10 000 default turns need ~110 000)."""
_CENTRE_EPS_M = 1e-9


@dataclass(frozen=True, eq=False)
class PlacedPiece:
    """One pass of the driving order.

    ``index``: 0-based position in the layout. ``entry``: its layout entry (kind, line).
    ``piece``: the piece value (for a re-entry: the physical crossroads' piece).
    ``world_from_piece``: pose of the piece frame in the world (re-entry: the physical
    crossroads' pose). ``entry_world`` / ``exit_world``: where this pass enters and leaves
    (re-entry: the matched side port, and the opposite side port).
    ``revisit_of``: index of the physical crossroads this pass re-enters, else ``None``.
    ``side_forward``: re-entry travels the side road side_in -> side_out (``True``) or back.
    """

    index: int
    entry: LayoutEntry
    piece: Piece
    world_from_piece: Pose2
    entry_world: Pose2
    exit_world: Pose2
    revisit_of: int | None = None
    side_forward: bool = True

    @property
    def line(self) -> int:
        return self.entry.line

    @property
    def kind(self) -> PieceType:
        return self.entry.kind

    @property
    def revisit(self) -> bool:
        return self.revisit_of is not None

    @property
    def length_m(self) -> float:
        """Driving length of this pass."""
        return self.piece.length_m

    def centreline_world(self) -> np.ndarray:
        """``(N, 2)`` world points of this pass, in driving order."""
        if self.revisit_of is None:
            return self.world_from_piece.apply(self.piece.centreline)
        pts = self.world_from_piece.apply(self.piece.side_centreline)
        return pts if self.side_forward else pts[::-1]


@dataclass(frozen=True)
class ReEntry:
    """A second (or later) pass through a crossroads: pass ``index`` re-enters physical
    piece ``of_index`` at ``port`` (``"side_in"`` or ``"side_out reversed"``) with a
    position error ``error_m`` and heading error ``error_rad`` (absolute, wrapped).
    ``pass_number`` is 2 for the intended crossing; ``params_differ`` if its line gave
    parameters different from the physical crossroads'."""

    index: int
    of_index: int
    port: str
    error_m: float
    error_rad: float
    pass_number: int = 2
    params_differ: bool = False


@dataclass(frozen=True)
class Track:
    """A chained layout. ``passes``: every layout entry placed, in driving order.
    ``reentries``: crossroads re-entries. ``start_pose``: the layout origin (identity)."""

    layout: Layout
    passes: tuple[PlacedPiece, ...]
    reentries: tuple[ReEntry, ...]

    @property
    def start_pose(self) -> Pose2:
        return Pose2()

    @property
    def end_pose(self) -> Pose2:
        return self.passes[-1].exit_world

    @property
    def physical(self) -> tuple[PlacedPiece, ...]:
        """Passes that are physical pieces (re-entries excluded)."""
        return tuple(p for p in self.passes if not p.revisit)

    def closure_error(self) -> tuple[float, float]:
        """Final exit vs start: position error (m), heading error (rad)."""
        return self.end_pose.distance_to(self.start_pose)

    @property
    def length_m(self) -> float:
        """Driving length of one lap (every pass)."""
        return float(sum(p.length_m for p in self.passes))

    def centreline(self) -> np.ndarray:
        """``(N, 2)`` closed loop in driving order; the closing point is not repeated."""
        parts = [p.centreline_world() for p in self.passes]
        pts = np.vstack([parts[0]] + [q[1:] for q in parts[1:]])
        if len(pts) > 1 and np.hypot(*(pts[-1] - pts[0])) < 1e-6:
            pts = pts[:-1]
        return pts

    def lighting(self):
        """The layout's light (``worlds.lighting.TrackLighting``) with a shade over each TUNNEL
        piece: its length, the road's width plus its walls, letting its ``transmission``
        through."""
        from pieces.library import TUNNEL_WALL_M
        from worlds.lighting import Shade

        base = self.layout.lighting
        shades = tuple(Shade(x, y, length, width + 2.0 * TUNNEL_WALL_M, yaw, transmission)
                       for x, y, yaw, length, width, _, _, transmission in self._tunnel_parts())
        if not shades:
            return base
        return dataclasses.replace(base, shades=tuple(base.shades) + shades)

    def tunnels(self) -> tuple:
        """``(x_m, y_m, yaw_rad, length_m, width_m, clearance_m, wall_m)`` of each TUNNEL piece
        (its middle, heading, length, the road's width; for the Gazebo world's roofs)."""
        return tuple(t[:7] for t in self._tunnel_parts())

    def _tunnel_parts(self) -> list[tuple]:
        from pieces.library import TUNNEL_CLEARANCE_M, TUNNEL_WALL_M

        out = []
        for p in self.passes:
            if p.kind is not PieceType.TUNNEL:
                continue
            length = p.piece.length_m
            (cx, cy), = p.world_from_piece.apply(np.array([[length / 2.0, 0.0]]))
            out.append((float(cx), float(cy), p.world_from_piece.yaw_rad, length,
                        self.layout.settings.road_width_m, TUNNEL_CLEARANCE_M, TUNNEL_WALL_M,
                        float(p.piece.params["transmission"])))
        return out

    def terrain(self):
        """The track's hills (:class:`worlds.terrain.Terrain`): one :class:`~worlds.terrain.Hill`
        per HILL piece, entry at the piece's entry, as wide as the road (empty: a flat track)."""
        from worlds.terrain import Hill, Terrain

        return Terrain(tuple(
            Hill(p.world_from_piece.x_m, p.world_from_piece.y_m, p.world_from_piece.yaw_rad,
                 p.piece.length_m, float(p.piece.params["height_m"]), self.layout.settings.road_width_m)
            for p in self.passes if p.kind is PieceType.HILL))

    def course_sections(self) -> list[tuple[float, float]]:
        """Arc length (m) along :meth:`centreline` where each pass starts and ends, in
        driving order (the polyline's own arc length: a little under ``length_m`` on arcs)."""
        out, s = [], 0.0
        for p in self.passes:
            pts = p.centreline_world()
            length = float(np.hypot(*np.diff(pts, axis=0).T).sum())
            out.append((s, s + length))
            s += length
        return out

    @property
    def start_finish(self) -> PlacedPiece | None:
        """The first START_FINISH pass, or ``None``."""
        return next((p for p in self.passes if p.kind is PieceType.START_FINISH), None)

    def finish_gate(self) -> tuple[Pose2, float] | None:
        """World pose of the START_FINISH marking centre (heading along the piece) and the
        gate half width (lane / 2 + edge line), or ``None`` without a START_FINISH."""
        sf = self.start_finish
        if sf is None:
            return None
        s = self.layout.settings
        return sf.world_from_piece @ sf.piece.ports["finish"], s.lane_width_m / 2 + s.edge_width_m

    def car_start_pose(self) -> Pose2:
        """START_FINISH_BEFORE_M before the finish marking, else the layout's start pose."""
        gate = self.finish_gate()
        if gate is None:
            return self.start_pose
        return gate[0] @ Pose2(-START_BEFORE_FINISH_M, 0.0, 0.0)

    @cached_property
    def world_footprints(self) -> dict[str, list]:
        """World-placed shapely footprints of the physical pieces, in their order:
        ``{"lane": [...], "edges": [...], "marking": [... or None], "road": [...]}``."""
        out: dict[str, list] = {"lane": [], "edges": [], "marking": [], "road": []}
        for p in self.physical:
            m = p.world_from_piece.as_shapely_affine()
            out["lane"].append(affinity.affine_transform(p.piece.lane, m))
            out["edges"].append(affinity.affine_transform(p.piece.edges, m))
            mk = p.piece.marking
            out["marking"].append(None if mk is None else affinity.affine_transform(mk, m))
            out["road"].append(affinity.affine_transform(p.piece.footprint, m))
        return out


def _crossroads_centre(world_from_piece: Pose2, piece: Piece) -> np.ndarray:
    mid = 0.5 * (np.array([piece.exit.x_m, piece.exit.y_m]))
    return world_from_piece.apply(mid)[0]


def chain(layout: Layout) -> Track:
    """Place the layout's pieces. Raises :class:`LayoutError` at the entry's line when a
    piece cannot be built (e.g. a radius tighter than half the road width)."""
    cache: dict[tuple, Piece] = {}
    passes: list[PlacedPiece] = []
    reentries: list[ReEntry] = []
    crossroads = _Crossroads()
    pass_count: dict[int, int] = {}
    vertices = 0
    cur = Pose2()
    for index, entry in enumerate(layout.entries):
        kwargs = layout.piece_kwargs(entry)
        key = (entry.kind, tuple(sorted(kwargs.items())))
        piece = cache.get(key)
        if piece is None:
            try:
                piece = make_piece(entry.kind, layout.settings, **kwargs)
            except PieceError as exc:
                message = layout.layout_names(str(exc), entry)
                raise layout.error(entry.line, f"{entry.describe()}: {message}") from None
            cache[key] = piece
        vertices += len(piece.centreline)
        if vertices > MAX_TRACK_VERTICES:
            raise layout.error(entry.line, (
                f"track too detailed: the curves up to this line need more than "
                f"{MAX_TRACK_VERTICES} centreline points (raise @arc_tolerance, or use fewer "
                "or smaller curves)"))
        world = cur @ piece.entry.inverse()
        if entry.kind is PieceType.CROSSROADS:
            centre = _crossroads_centre(world, piece)
            hit = crossroads.find(centre, piece.length_m)
            if hit is not None:
                placed, reentry = _reenter(index, entry, cur, passes[hit], piece,
                                           pass_count.get(hit, 1) + 1)
                pass_count[hit] = reentry.pass_number
                passes.append(placed)
                reentries.append(reentry)
                cur = placed.exit_world
                continue
            crossroads.add(index, centre, piece.length_m)
        placed = PlacedPiece(index, entry, piece, world, world @ piece.entry, world @ piece.exit)
        passes.append(placed)
        cur = placed.exit_world
    return Track(layout, tuple(passes), tuple(reentries))


class _Crossroads:
    """The physical crossroads placed so far: pass index, centre and length, searched in
    one vectorised step (a layout may hold thousands)."""

    def __init__(self) -> None:
        self.index: list[int] = []
        self.centre = np.zeros((0, 2))
        self.size = np.zeros(0)

    def add(self, index: int, centre: np.ndarray, length_m: float) -> None:
        self.index.append(index)
        self.centre = np.vstack([self.centre, centre[None, :]])
        self.size = np.append(self.size, length_m)

    def find(self, centre: np.ndarray, length_m: float) -> int | None:
        """The nearest crossroads closer than end to end to one at ``centre``, or ``None``."""
        if not self.index:
            return None
        d = np.hypot(*(self.centre - centre).T)
        near = d < 0.5 * (self.size + length_m) - _CENTRE_EPS_M
        if not near.any():
            return None
        d = np.where(near, d, math.inf)
        return self.index[int(np.argmin(d))]


def _reenter(index: int, entry: LayoutEntry, cur: Pose2, phys: PlacedPiece, piece: Piece,
             pass_number: int) -> tuple[PlacedPiece, ReEntry]:
    w = phys.world_from_piece
    half = 0.5 * phys.piece.length_m
    side_in = w @ phys.piece.ports["side_in"]
    side_out_rev = (w @ phys.piece.ports["side_out"]).reversed()
    e_in = cur.distance_to(side_in)
    e_out = cur.distance_to(side_out_rev)
    # Weigh the heading error by the half size (lever arm) to choose the nearer port.
    if e_in[0] + half * e_in[1] <= e_out[0] + half * e_out[1]:
        port, err, forward = "side_in", e_in, True
        entry_w, exit_w = side_in, w @ phys.piece.ports["side_out"]
    else:
        port, err, forward = "side_out reversed", e_out, False
        entry_w, exit_w = side_out_rev, (w @ phys.piece.ports["side_in"]).reversed()
    placed = PlacedPiece(index, entry, phys.piece, w, entry_w, exit_w, revisit_of=phys.index,
                         side_forward=forward)
    differ = piece != phys.piece
    return placed, ReEntry(index, phys.index, port, err[0], err[1], pass_number, differ)
