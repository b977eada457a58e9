"""Parametric NXP Cup track pieces: exact 2D footprints, lazy watertight meshes, SE(2) ports.

Piece types (named as in the thesis): STRAIGHT, STRAIGHT_SHORT, CROSSROADS, TURN_LEFT,
TURN_RIGHT, CHICANE_LEFT, CHICANE_RIGHT, START_FINISH. ``from pieces import TURN_LEFT,
straight`` works: each type is also a module constant.

Local frame of every piece: the entry port is the identity pose (origin at the centre of the
entry edge, heading +x into the piece). Ports are :class:`Pose2` heading in the direction of
travel. Chaining is pose algebra only::

    world_from_next = world_exit_of_previous @ next.ports["entry"].inverse()

Python API (metres and radians, keyword-only; bad values raise :class:`PieceError`, a
``ValueError``, whose message names the parameter, its value and the expected range):

    TrackSettings(lane_width_m=0.55, edge_width_m=0.020, thickness_m=0.01,
                  arc_tolerance_m=0.001)             # track-wide, frozen; road_width_m
    straight(*, length_m=1.0, settings)              # exit Pose2(L, 0, 0)
    straight_short(*, length_m=0.5, settings)
    turn(*, angle_rad=pi/4, radius_m=0.8, direction=+1|-1, settings)
    turn_left(...), turn_right(...)                  # exit Pose2(R sin a, +-R(1-cos a), +-a)
    chicane(*, length_m=1.0, offset_m=0.20, direction=+1|-1, settings)
    chicane_left(...), chicane_right(...)            # exit Pose2(L, +-offset, 0)
    crossroads(*, length_m=0.6, settings)            # + side_in / side_out ports
    start_finish(*, length_m=1.0, mark_length_m=0.05, settings)   # + "finish" port
    make_piece(kind, settings=TrackSettings(), **internal_params) -> Piece
    piece_from_layout(kind, params: Mapping[str, float], settings) -> Piece
    PARAMS[kind][layout_name] -> ParamSpec(name, unit, default, lo, hi, lo_open, hi_open,
                                           internal, to_internal); .check(v), .range_text()
    SETTINGS_PARAMS[layout_name] -> ParamSpec;  TrackSettings.from_layout(mapping)
    pieces.mesh.extrude_footprint(geom, thickness_m) -> trimesh.Trimesh (watertight)
    pieces.mesh.extrude_arrays(geom, thickness_m) -> (vertices, faces)  (no trimesh)

Layout-file parameter names and units (``PARAMS``): STRAIGHT / STRAIGHT_SHORT / CROSSROADS
``length`` (m); TURN_* ``radius`` (m), ``angle`` (deg, (0, 180]); CHICANE_* ``length``,
``offset`` (m); START_FINISH ``length``, ``mark_length`` (m). Degrees exist only there.

A :class:`Piece` is frozen: ``kind``, ``settings``, ``params`` (read-only, internal units),
``lane`` / ``edges`` / ``marking`` (shapely footprints, pairwise disjoint; ``marking`` is
None except on START_FINISH), ``centreline`` ((N, 2) read-only, entry -> exit; crossroads:
the main road, plus ``side_centreline``), ``ports`` (read-only name -> Pose2),
``length_m``, ``min_radius_m`` (inf when straight), and lazily built ``footprint``,
``lane_mesh``, ``edge_mesh``, ``marking_mesh`` (trimesh, z in [0, thickness_m]).

Geometry: black edge lines lie OUTSIDE the white lane (road = 0.55 + 2 * 0.020 = 0.59 m).
Arcs are exact annulus sectors sampled at common angles (segments from the sagitta
tolerance) with their end edges exactly on the port normals, so adjacent pieces meet with
neither overlap nor gap. Chicane: two opposite arcs of angle ``theta = 2 atan(offset/L)``
and radius ``R = L / (2 sin theta)`` (defaults: theta = 22.62 deg, R = 1.30 m). START_FINISH:
the finish bar (black, full lane width, 0.05 m along travel, at mid-piece) is cut OUT of the
white lane, so no two footprints overlap and nothing z-fights. CROSSROADS: white = union of
two perpendicular lanes of length C; the edge lines are broken where the other road passes,
leaving four L-shaped stubs at the corners; C must be at least the road width.
The side road, travelled towards +y, runs side_in = Pose2(C/2, -C/2, pi/2) -> side_out =
Pose2(C/2, C/2, pi/2); travelled the other way it runs side_out.reversed() ->
side_in.reversed().

Why the defaults close the thesis figure-8 (Figure 4.2: X SS TL TL S S TL TL TL TL S S SS X
SS TR TR TR TR TR TR SS; X = CROSSROADS C = 0.6 m, SS = 0.5 m, S = 1.0 m, turns 45 deg of
centreline radius R = 0.8 m). Start at the crossroads entry, heading +x. After X and SS,
x = C + s; a left quarter turn moves x by +R, the half turn after the two straights by -2R,
so the downward leg runs at x = C + s - R. It must pass through the crossroads centre
x = C/2, hence R = s + C/2 = 0.5 + 0.3 = 0.8 m. The same condition makes the downward leg
reach the crossroads' top edge: y = R + 2S - 2S - s = R - s = C/2 = 0.3 m. After the second
crossing (y = -C/2 - s = -0.8 m) the six right turns (270 deg about the centre (C/2 - R,
-C/2 - s) = (-0.5, -0.8)) end heading +x at (C/2 - R, -C/2 - s + R) = (-0.5, 0.0), and the
last SS returns to (0, 0). Pose-algebra closure error with these numbers: ~1e-15 m, 0 rad.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from .pose import Pose2, wrap_angle
from .spec import KITS, PARAMS, SETTINGS_PARAMS, Kit, ParamSpec, PieceError, PieceType, TrackSettings

if TYPE_CHECKING:  # for type checkers and IDEs; at run time these load on first use
    from . import mesh
    from .library import (DEFAULT_SETTINGS, chicane, chicane_geometry, chicane_left, chicane_right,
                          crossroads, extender, make_piece, piece_from_layout, speed_limit_end,
                          speed_limit_start, start_finish, straight, straight_short, tunnel, turn, turn_left,
                          turn_right, wave, wave_geometry)
    from .piece import Piece

# Lazy exports (PEP 562): shapely loads with the first piece, trimesh and manifold3d with the
# first mesh, so ``import pieces.pose`` (e.g. for ``Pose2`` alone) costs numpy only.
_EXPORTS = {"Piece": "pieces.piece", "mesh": None}
_EXPORTS.update((name, "pieces.library") for name in (
    "DEFAULT_SETTINGS", "chicane", "chicane_geometry", "chicane_left", "chicane_right",
    "crossroads", "extender", "make_piece", "piece_from_layout", "speed_limit_end", "speed_limit_start",
    "start_finish", "straight", "straight_short", "tunnel", "hill", "turn", "turn_left", "turn_right", "wave",
    "wave_geometry"))

STRAIGHT = PieceType.STRAIGHT
STRAIGHT_SHORT = PieceType.STRAIGHT_SHORT
CROSSROADS = PieceType.CROSSROADS
TURN_LEFT = PieceType.TURN_LEFT
TURN_RIGHT = PieceType.TURN_RIGHT
CHICANE_LEFT = PieceType.CHICANE_LEFT
CHICANE_RIGHT = PieceType.CHICANE_RIGHT
START_FINISH = PieceType.START_FINISH
EXTENDER = PieceType.EXTENDER
SPEED_LIMIT_START = PieceType.SPEED_LIMIT_START
SPEED_LIMIT_END = PieceType.SPEED_LIMIT_END
WAVE = PieceType.WAVE
TUNNEL = PieceType.TUNNEL
HILL = PieceType.HILL

__all__ = [
    "Pose2", "wrap_angle", "KITS", "Kit", "PARAMS", "SETTINGS_PARAMS", "ParamSpec", "PieceError", "PieceType",
    "TrackSettings", "Piece", "DEFAULT_SETTINGS", "chicane", "chicane_geometry", "chicane_left",
    "chicane_right", "crossroads", "extender", "make_piece", "piece_from_layout", "speed_limit_end",
    "speed_limit_start", "start_finish", "straight", "tunnel", "hill", "wave", "wave_geometry",
    "straight_short", "turn", "turn_left", "turn_right", "mesh",
    "STRAIGHT", "STRAIGHT_SHORT", "CROSSROADS", "TURN_LEFT", "TURN_RIGHT", "CHICANE_LEFT",
    "CHICANE_RIGHT", "START_FINISH", "EXTENDER", "SPEED_LIMIT_START", "SPEED_LIMIT_END", "WAVE", "TUNNEL", "HILL",
]


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'pieces' has no attribute {name!r}")
    module = _EXPORTS[name]
    value = importlib.import_module(f"pieces.{name}") if module is None else getattr(
        importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
