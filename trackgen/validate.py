"""Checks of a chained track, each with a stated tolerance.

Every problem is one :class:`Problem` whose ``str`` is ``path:line: message`` naming the
layout line, the piece and the measured error. Warnings do not make a track invalid.

Checks and tolerances (module constants; tolerances in metres are multiplied by the layout's
``@scale``, areas by its square, so a scaled layout passes exactly when the unscaled one does):
  closure       final exit vs start pose: CLOSURE_TOL_M, CLOSURE_TOL_RAD; the message says
                what is wrong (:mod:`trackgen.closure`: the total turning and what would close
                it, the pieces that would close the gap) and is reported at the line of the
                cause when one turn or one run of straights can be named, else at the last
                piece's line
  continuity    previous exit vs next entry at every joint: JOINT_TOL_M, JOINT_TOL_RAD
                (exact by construction; still checked)
  re-entry      a crossroads crossed a second time: the pose vs its side port,
                REENTRY_TOL_M, REENTRY_TOL_RAD; at most two passes; same parameters
  overlap       road footprints (lane + edges + marking) of non-adjacent physical pieces
                intersect by more than OVERLAP_TOL_M2 (the crossing of a crossroads is one
                physical piece, so it is no overlap); STRtree, not all pairs, in chunks;
                stops after MAX_OVERLAPS overlaps (bounded time and memory)
  turn radius   every piece's tightest centreline radius >= the car's minimum turning
                radius wheelbase / tan(steering limit) (thesis eq. 5.1), RADIUS_TOL_M slack
  hills         every HILL no steeper than the car can climb (gravity along the slope below the
                drive's acceleration limit, and below half the tyres' grip: the driven rear
                axle carries about half the weight) and its crest and feet no tighter than the
                chassis clears (:class:`HillLimits`, from the car file)
  road width    the road (lane and both lines) wider than the car over its tyres (chassis.track_m +
                wheels.width_m): else the car stands off the road from the start
  start/finish  at most one START_FINISH; none is a warning (laps are then timed at the
                start pose)
  meshes        lane / edges / markings meshes are watertight after a binary STL round
                trip (float32), see :func:`check_meshes` (run by trackgen.build.check_layout
                only when the other checks pass)

At most MAX_PROBLEMS problems are listed (errors first); the rest are summarised in one
more line (``check="summary"``, its ``hidden`` count says how many it stands for).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from pieces.spec import PieceType

from .chain import Track


CLOSURE_TOL_M = 1e-6
CLOSURE_TOL_RAD = 1e-6
JOINT_TOL_M = 1e-9
JOINT_TOL_RAD = 1e-9
REENTRY_TOL_M = 1e-6
REENTRY_TOL_RAD = 1e-6
OVERLAP_TOL_M2 = 1e-6
RADIUS_TOL_M = 1e-9
MAX_PROBLEMS = 30
"""Problems listed one per line; more are summarised in one line."""
MAX_OVERLAPS = 20
"""The overlap search stops after this many overlaps (one more line says so)."""
MAX_OVERLAP_PAIRS = 200_000
"""Most pairs of touching pieces whose overlap is measured (bounded time)."""
_OVERLAP_CHUNK = 32


@dataclass(frozen=True)
class Problem:
    """One finding. ``line`` is 1-based or ``None`` (a file as a whole); ``check`` names
    the check (``closure``, ``continuity``, ``reentry``, ``overlap``, ``turn_radius``,
    ``start_finish``, ``mesh``, ``folder``, ``summary``); ``warning`` findings do not fail
    validation. ``hidden``: for a summary, how many problems it stands for."""

    path: str
    line: int | None
    message: str
    check: str
    warning: bool = False
    hidden: int = 0

    def __str__(self) -> str:
        where = self.path if self.line is None else f"{self.path}:{self.line}"
        return f"{where}: {'warning: ' if self.warning else ''}{self.message}"


def errors(problems: list[Problem]) -> list[Problem]:
    """The problems that fail validation (warnings removed)."""
    return [p for p in problems if not p.warning]


def count_errors(problems: list[Problem]) -> int:
    """How many errors ``problems`` stand for (a summary line counts what it hides)."""
    return sum(p.hidden or 1 for p in errors(problems))


def summarise(problems: list[Problem], path: str, limit: int = MAX_PROBLEMS) -> list[Problem]:
    """At most ``limit`` problems (errors first, then by line) plus one summary line."""
    if len(problems) <= limit:
        return problems
    ranked = sorted(problems, key=lambda p: (p.warning, p.line or 0))
    shown, rest = ranked[:limit], ranked[limit:]
    by_check: dict[str, int] = {}
    for p in rest:
        by_check[p.check] = by_check.get(p.check, 0) + (p.hidden or 1)
    hidden_errors = sum(p.hidden or 1 for p in rest if not p.warning)
    total = sum(by_check.values())
    what = ", ".join(f"{k} {v}" for k, v in sorted(by_check.items()))
    summary = Problem(path, None, f"... and {total} more problem(s) not listed ({what})",
                      "summary", warning=hidden_errors == 0, hidden=hidden_errors or total)
    return sorted(shown, key=lambda p: (p.line or 0)) + [summary]


def _deg(rad: float) -> float:
    return math.degrees(rad)


def validate_track(track: Track, min_turn_radius_m: float, *, meshes: dict | None = None,
                   hill_limits: HillLimits | None = None, car_width_m: float | None = None) -> list[Problem]:
    """All checks of the module docstring; ``meshes`` (role -> trimesh) adds the mesh check,
    ``hill_limits`` (the car's, :meth:`HillLimits.of_car`) the hill check, ``car_width_m`` (over
    the tyres) the road width check.
    Returns problems sorted by line (stable)."""
    path = track.layout.path
    scale = track.layout.scale
    out: list[Problem] = []
    out += _check_closure(track, path, scale)
    out += _check_joints(track, path)
    out += _check_reentries(track, path, scale)
    out += _check_overlaps(track, path, scale)
    out += _check_radius(track, path, min_turn_radius_m)
    if hill_limits is not None:
        out += _check_hills(track, path, hill_limits)
    if car_width_m is not None:
        out += _check_road_width(track, path, car_width_m)
    out += _check_start_finish(track, path)
    if meshes is not None:
        first_line = track.passes[0].line
        out += [Problem(path, first_line, msg, "mesh") for msg in check_meshes(meshes)]
    return summarise(sorted(out, key=lambda p: (p.line or 0)), path)


def _check_closure(track: Track, path: str, scale: float = 1.0) -> list[Problem]:
    from .closure import explain_closure

    err_m, err_rad = track.closure_error()
    tol_m = CLOSURE_TOL_M * scale
    if err_m <= tol_m and err_rad <= CLOSURE_TOL_RAD:
        return []
    last = track.passes[-1]
    line, hint = explain_closure(track, tol_m, CLOSURE_TOL_RAD)
    return [Problem(path, line or last.line, (
        f"track does not close: the exit of {last.kind.name} (piece {last.index + 1}, line "
        f"{last.line}) misses the start pose by {err_m:.3f} m / {_deg(err_rad):.1f} deg "
        f"(tolerance {tol_m:g} m / {CLOSURE_TOL_RAD:g} rad); {hint}"), "closure")]


def _check_joints(track: Track, path: str) -> list[Problem]:
    out = []
    for prev, cur in zip(track.passes, track.passes[1:]):
        if cur.revisit:
            continue  # checked against the side port with the re-entry tolerance
        err_m, err_rad = prev.exit_world.distance_to(cur.entry_world)
        if err_m > JOINT_TOL_M or err_rad > JOINT_TOL_RAD:
            out.append(Problem(path, cur.line, (
                f"{cur.kind.name} (piece {cur.index + 1}) does not join the previous piece: "
                f"off by {err_m:.3g} m / {_deg(err_rad):.3g} deg "
                f"(tolerance {JOINT_TOL_M:g} m / {JOINT_TOL_RAD:g} rad)"), "continuity"))
    return out


def _check_reentries(track: Track, path: str, scale: float = 1.0) -> list[Problem]:
    out = []
    tol_m = REENTRY_TOL_M * scale
    for r in track.reentries:
        p, first = track.passes[r.index], track.passes[r.of_index]
        if r.pass_number > 2:
            out.append(Problem(path, p.line, (
                f"CROSSROADS crossed {r.pass_number} times: the crossroads on line {first.line} "
                "has one side road (at most two passes)"), "reentry"))
        if r.error_m > tol_m or r.error_rad > REENTRY_TOL_RAD:
            out.append(Problem(path, p.line, (
                f"CROSSROADS re-entry misses side port of the crossroads on line {first.line} by "
                f"{r.error_m:.3f} m / {_deg(r.error_rad):.1f} deg "
                f"(tolerance {tol_m:g} m / {REENTRY_TOL_RAD:g} rad){_reentry_fix(track, r)}"), "reentry"))
        if r.params_differ:
            out.append(Problem(path, p.line, (
                f"CROSSROADS re-entry {p.entry.describe()} differs from the crossroads on line "
                f"{first.line} ({first.entry.describe()}): a crossroads crossed twice is one "
                "piece; give the parameters once"), "reentry"))
    return out


def _reentry_fix(track: Track, r) -> str:
    """Where the track arrives at a crossroads' side port, in the port's own frame, and what
    would make it arrive there (the pieces before it longer or shorter)."""
    if r.index == 0:
        return ""
    port = track.passes[r.index].entry_world
    arrival = port.inverse() @ track.passes[r.index - 1].exit_world
    along, across = arrival.x_m, arrival.y_m
    along, across = (v if abs(v) >= 5e-4 else 0.0 for v in (along, across))  # no "-0.000"
    text = (f": it arrives {abs(along):.3f} m {'before' if along < 0 else 'past'} the port and "
            f"{abs(across):.3f} m to its {'left' if across > 0 else 'right'}, heading "
            f"{_deg(abs(arrival.yaw_rad)):.1f} deg {'left' if arrival.yaw_rad > 0 else 'right'} of it")
    if abs(along) >= 5e-4 and abs(across) < 5e-4 and abs(arrival.yaw_rad) < REENTRY_TOL_RAD:
        text += (f"; the pieces before it are {abs(along):.3f} m too "
                 f"{'short' if along < 0 else 'long'} (along the side road)")
    elif abs(across) >= 5e-4 and abs(arrival.yaw_rad) < REENTRY_TOL_RAD:
        text += _reentry_runs(track, r)
    return text


def _reentry_runs(track: Track, r) -> str:
    """A re-entry that arrives beside its port (heading right): the straight pieces between the
    crossroads' first pass and the re-entry that run along the miss ``d`` (they move the arrival
    by their change of length, as the closure check names them: :mod:`trackgen.closure`) are
    together ``|d|`` too long, or those running against it too short; "" when none does."""
    from .closure import heading_deg, lines_text, runs_along

    port = track.passes[r.index].entry_world
    end = track.passes[r.index - 1].exit_world
    dist = math.hypot(end.x_m - port.x_m, end.y_m - port.y_m)
    miss = math.atan2(end.y_m - port.y_m, end.x_m - port.x_m)
    long_, short = runs_along(track.passes[r.of_index + 1:r.index], miss, dist, 5e-4)
    parts = []
    if long_:
        parts.append(f"the pieces heading {heading_deg(miss):.1f} deg ({lines_text(long_)}) are {dist:.3f} m "
                     "too long in total")
    if short:
        parts.append(f"those heading {heading_deg(miss + math.pi):.1f} deg ({lines_text(short)}) {dist:.3f} m "
                     "too short")
    return "; " + ", or ".join(parts) if parts else ""


def _adjacent_pairs(track: Track) -> set[tuple[int, int]]:
    """Pairs of physical-piece positions joined in driving order (incl. last -> first)."""
    position = {p.index: i for i, p in enumerate(track.physical)}
    seq = [position[p.revisit_of if p.revisit else p.index] for p in track.passes]
    pairs = set()
    for a, b in zip(seq, seq[1:] + seq[:1]):
        pairs.add((min(a, b), max(a, b)))
    return pairs


def _check_overlaps(track: Track, path: str, scale: float = 1.0) -> list[Problem]:
    """Overlapping non-adjacent pieces, searched a chunk of pieces at a time; stops after
    MAX_PROBLEMS + 1 overlaps (the summary line says the rest was not searched)."""
    roads = track.world_footprints["road"]
    phys = track.physical
    if len(roads) < 2:
        return []
    tol_m2 = OVERLAP_TOL_M2 * scale * scale
    tree = shapely.STRtree(roads)
    geoms = np.asarray(roads, dtype=object)
    adjacent = _adjacent_pairs(track)
    out: list[Problem] = []
    pairs = 0
    for start in range(0, len(roads), _OVERLAP_CHUNK):
        left, right = tree.query(geoms[start:start + _OVERLAP_CHUNK], predicate="intersects")
        left = left + start
        keep = left < right
        left, right = left[keep], right[keep]
        mask = np.array([(int(a), int(b)) not in adjacent for a, b in zip(left, right)], dtype=bool)
        if not mask.any():
            continue
        order = np.lexsort((right[mask], left[mask]))
        left, right = left[mask][order], right[mask][order]
        for k in range(0, left.size, _OVERLAP_CHUNK):
            lk, rk = left[k:k + _OVERLAP_CHUNK], right[k:k + _OVERLAP_CHUNK]
            pairs += lk.size
            areas = shapely.area(shapely.intersection(geoms[lk], geoms[rk]))
            for a, b, area in zip(lk, rk, areas):
                if area > tol_m2:
                    pa, pb = phys[int(a)], phys[int(b)]
                    out.append(Problem(path, pb.line, (
                        f"{pb.kind.name} (piece {pb.index + 1}) overlaps {pa.kind.name} (piece "
                        f"{pa.index + 1}, line {pa.line}) by {area:.4g} m^2 "
                        f"(tolerance {tol_m2:g} m^2)"), "overlap"))
                    if len(out) >= MAX_OVERLAPS:
                        break
            if len(out) >= MAX_OVERLAPS or pairs > MAX_OVERLAP_PAIRS:
                out.append(Problem(path, None, (
                    f"overlap search stopped after {len(out)} overlaps (at piece "
                    f"{phys[int(a)].index + 1}, {pairs} touching pairs measured): further "
                    "overlaps are not listed"), "overlap", warning=not out))
                return out
    return out


def _check_radius(track: Track, path: str, min_turn_radius_m: float) -> list[Problem]:
    out = []
    for p in track.physical:
        r = p.piece.min_radius_m
        if r < min_turn_radius_m - RADIUS_TOL_M:
            what = ("the smoothest path through its lane has radius" if p.kind is PieceType.WAVE
                    else "centreline radius")
            out.append(Problem(path, p.line, (
                f"{p.entry.describe()} (piece {p.index + 1}): {what} {r:.3f} m is "
                f"tighter than the car's minimum turning radius {min_turn_radius_m:.3f} m "
                "(wheelbase / tan(steering limit), thesis eq. 5.1)"), "turn_radius"))
    return out


@dataclass(frozen=True)
class HillLimits:
    """What a car can drive over (:meth:`of_car`): the steepest slope (rad) and the tightest
    radius of curvature at a crest or a foot (m)."""

    max_slope_rad: float
    min_radius_m: float
    slope_why: str
    radius_why: str

    @classmethod
    def of_car(cls, car) -> "HillLimits":
        """From a ``vehicle.description.CarDescription``: climbing needs ``g sin(slope) <
        drive.max_accel_mps2`` and ``tan(slope) < mu / 2`` (ours: half the weight on the driven
        axle); the chassis box, ``clearance = cog_height - height / 2`` above the ground, clears a
        crest of radius ``R`` when the sag between the axles, ``wheelbase^2 / (8 R)``, and an
        overhang's dip into a foot, ``overhang^2 / (2 R)``, stay below it."""
        g = 9.81
        climb = math.asin(min(1.0, car.drive.max_accel_mps2 / g))
        grip = math.atan(0.5 * car.wheels.friction_mu)
        ch = car.chassis
        clearance = max(ch.cog_height_m - 0.5 * ch.height_m, 1e-6)
        overhang = max(ch.rear_overhang_m, ch.length_m - ch.rear_overhang_m - ch.wheelbase_m, 0.0)
        radius = max(ch.wheelbase_m ** 2 / (8.0 * clearance), overhang ** 2 / (2.0 * clearance))
        slope_why = ("the drive's acceleration limit (drive.max_accel_mps2 = "
                     f"{car.drive.max_accel_mps2:g} m/s^2) against gravity" if climb <= grip else
                     f"half the tyres' grip (wheels.friction_mu = {car.wheels.friction_mu:g})")
        return cls(min(climb, grip), radius, slope_why,
                   f"the chassis's {clearance * 1000:.0f} mm ground clearance over its wheelbase and overhangs")


def _check_hills(track: Track, path: str, limits: HillLimits) -> list[Problem]:
    out = []
    for p in track.physical:
        if p.kind is not PieceType.HILL:
            continue
        length, height = p.piece.length_m, float(p.piece.params["height_m"])
        slope = math.atan(math.pi * height / length)
        radius = length ** 2 / (2.0 * math.pi ** 2 * height)
        where = f"{p.entry.describe()} (piece {p.index + 1})"
        if slope > limits.max_slope_rad:
            out.append(Problem(path, p.line, (
                f"{where}: slopes {_deg(slope):.1f} deg at its steepest (pi height / length), "
                f"steeper than the car climbs, {_deg(limits.max_slope_rad):.1f} deg "
                f"({limits.slope_why}): make it lower or longer"), "hill"))
        if radius < limits.min_radius_m:
            out.append(Problem(path, p.line, (
                f"{where}: its crest and feet curve on a radius of {radius:.3f} m (length^2 / "
                f"(2 pi^2 height)), tighter than the car clears, {limits.min_radius_m:.3f} m "
                f"({limits.radius_why}): make it lower or longer"), "hill"))
    return out


def _check_road_width(track: Track, path: str, car_width_m: float) -> list[Problem]:
    s = track.layout.settings
    if s.road_width_m > car_width_m:
        return []
    lines = track.layout.setting_lines  # the setting that made it so, else the first piece
    scale = track.layout.scale
    shrunk = "scale" in lines and s.road_width_m / scale > car_width_m  # wide enough as written
    line = lines["scale"] if shrunk else next(
        (lines[k] for k in ("lane_width", "edge_width", "scale", "kit") if k in lines), track.passes[0].line)
    return [Problem(path, line, (
        f"the road is {s.road_width_m:.3f} m wide (@lane_width {s.lane_width_m:g} m and two "
        f"@edge_width {s.edge_width_m:g} m lines{f', after @scale {scale:g}' if scale != 1 else ''}), "
        f"narrower than the car over its tyres, "
        f"{car_width_m:.3f} m (chassis.track_m + wheels.width_m): it would stand off the road from the "
        "start"), "road_width")]


def _check_start_finish(track: Track, path: str) -> list[Problem]:
    sfs = [p for p in track.passes if p.kind is PieceType.START_FINISH]
    if not sfs:
        return [Problem(path, track.passes[0].line, (
            "no START_FINISH piece: the simulator then times laps at the start pose"),
            "start_finish", warning=True)]
    return [Problem(path, p.line, (
        f"second START_FINISH (piece {p.index + 1}; the first is on line {sfs[0].line}): "
        "a track has at most one"), "start_finish") for p in sfs[1:]]


def check_meshes(meshes: dict) -> list[str]:
    """Messages for meshes (:class:`trackgen.meshes.SlabMesh` or trimesh) that are empty or
    not watertight after an STL round trip (:func:`trackgen.meshes.watertight_after_stl`)."""
    from .meshes import watertight_after_stl

    out = []
    for role, mesh in meshes.items():
        if len(mesh.faces) == 0:
            out.append(f"{role} mesh is empty")
            continue
        ok, faces, euler = watertight_after_stl(mesh)
        if not ok:
            out.append(f"{role} mesh is not watertight after the STL round trip "
                       f"({faces} faces, Euler number {euler})")
    return out
