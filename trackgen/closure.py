"""Why a track does not close, in the layout's words (used by the closure check).

Two causes are told apart:

* **Heading**: a closed track turns by a multiple of 360 deg (0 for a figure 8). The
  turns' angles (TURN_LEFT +angle, TURN_RIGHT -angle; every other piece keeps its heading)
  are summed and compared with the nearest multiple: ``turns sum to 355 deg; 360 needed
  (5 deg short)``. When changing one line's turn by the difference gives an angle that
  other turns of the layout already use (an 85 among 90s), that line is the cause.
* **Position** (the headings close): the exit misses the start by a vector ``d``. A piece
  that keeps its heading (straights, START_FINISH, chicanes) moves everything after it by
  its change of length along its heading, so the pieces heading along ``-d`` are together
  ``|d|`` too short (or those heading along ``d`` too long). They are named when some are.
"""
from __future__ import annotations

import math

from pieces.spec import PieceType

from .chain import PlacedPiece, Track

_TURNS = {PieceType.TURN_LEFT: 1.0, PieceType.TURN_RIGHT: -1.0}
_RUNS = (PieceType.STRAIGHT, PieceType.STRAIGHT_SHORT, PieceType.START_FINISH,
         PieceType.CHICANE_LEFT, PieceType.CHICANE_RIGHT, PieceType.EXTENDER,
         PieceType.SPEED_LIMIT_START, PieceType.SPEED_LIMIT_END, PieceType.WAVE)
"""Pieces whose exit heading is their entry heading and whose length moves the exit along it."""
_MAX_LINES = 5


def turning_deg(p: PlacedPiece) -> float:
    """Signed heading change of one pass in degrees (left positive; re-entries 0)."""
    sign = _TURNS.get(p.kind)
    if sign is None or p.revisit:
        return 0.0
    return sign * math.degrees(p.piece.params["angle_rad"])


def lines_text(passes: list[PlacedPiece]) -> str:
    """``line 3`` / ``lines 3, 5`` (at most _MAX_LINES listed)."""
    lines = sorted({p.line for p in passes})
    more = f" and {len(lines) - _MAX_LINES} more" if len(lines) > _MAX_LINES else ""
    word = "line" if len(lines) == 1 else "lines"
    return f"{word} " + ", ".join(str(n) for n in lines[:_MAX_LINES]) + more


def heading_deg(rad: float) -> float:
    """Degrees in (-180, 180]."""
    deg = math.degrees(math.remainder(rad, 2.0 * math.pi))
    return 180.0 if deg <= -180.0 + 1e-9 else round(deg, 9) + 0.0  # no "-0.0 deg"


def runs_along(passes: list[PlacedPiece], direction_rad: float, dist_m: float, tol_m: float,
               tol_rad: float = math.inf) -> tuple[list[PlacedPiece], list[PlacedPiece]]:
    """The passes that move what follows them along ``direction_rad`` by their change of length
    (first passes of the ``_RUNS`` pieces heading along it, to ``tol_m`` sideways over ``dist_m``
    and ``tol_rad``), and those heading against it: ``(along, against)``."""
    along, against = [], []
    for p in passes:
        if p.kind not in _RUNS or p.revisit:
            continue
        off = math.remainder(p.entry_world.yaw_rad - direction_rad, 2.0 * math.pi)
        if dist_m * abs(math.sin(off)) > tol_m or abs(math.sin(off)) > tol_rad:
            continue
        (along if abs(off) < math.pi / 2 else against).append(p)
    return along, against


def explain_closure(track: Track, tol_m: float, tol_rad: float) -> tuple[int | None, str]:
    """``(line of the cause or None, text)`` for a track that does not close."""
    total = round(sum(turning_deg(p) for p in track.passes), 9) + 0.0  # no "1.42109e-14 deg"
    needed = 360.0 * round(total / 360.0)
    diff = needed - total
    tol_deg = math.degrees(tol_rad)
    if abs(diff) > tol_deg:
        return _heading_cause(track, total, needed, diff, tol_deg)
    return _position_cause(track, total, tol_m, tol_rad)


def _heading_cause(track: Track, total: float, needed: float, diff: float,
                   tol_deg: float) -> tuple[int | None, str]:
    text = (f"turns sum to {total:.6g} deg; {needed:.6g} needed "
            f"({abs(diff):.6g} deg {'too many' if abs(total) > abs(needed) else 'short'})")
    turns = [p for p in track.passes if turning_deg(p) != 0.0]
    lines_at: dict[float, set[int]] = {}   # angle (rounded to 1e-6 deg) -> up to 2 lines
    for p in turns:
        seen = lines_at.setdefault(round(abs(turning_deg(p)), 6), set())
        if len(seen) < 2:
            seen.add(p.line)
    for p in turns:
        angle = abs(turning_deg(p))
        fixed = angle + diff * (1.0 if turning_deg(p) > 0 else -1.0)
        if not 0.0 < fixed <= 180.0 + tol_deg:
            continue
        if lines_at.get(round(fixed, 6), set()) - {p.line}:
            return p.line, (f"{text}: the turn on line {p.line} ({p.entry.describe()}) is the odd "
                            f"one out; angle={fixed:.6g} would close the heading")
    return None, text + "; no single turn explains it"


def _position_cause(track: Track, total: float, tol_m: float,
                    tol_rad: float) -> tuple[int | None, str]:
    end = track.end_pose
    dx, dy = end.x_m - track.start_pose.x_m, end.y_m - track.start_pose.y_m
    dist = math.hypot(dx, dy)
    dx, dy = (v if abs(v) >= 5e-4 else 0.0 for v in (dx, dy))  # no "-0.000"
    text = (f"the headings close (turns sum to {total:.6g} deg) but the exit is {dist:.3f} m "
            f"from the start (dx = {dx:.3f} m, dy = {dy:.3f} m)")
    need = math.atan2(-dy, -dx)  # the direction the track still has to go
    short, long_ = runs_along(track.passes, need, dist, tol_m, tol_rad)
    if not short and not long_:
        return None, text + "; no straight piece runs along that gap"
    parts = []
    if short:
        parts.append(f"the pieces heading {heading_deg(need):.1f} deg ({lines_text(short)}) "
                     f"are {dist:.3f} m too short in total")
    if long_:
        back = heading_deg(need + math.pi)
        parts.append(f"those heading {back:.1f} deg ({lines_text(long_)}) {dist:.3f} m too long")
    first = (short or long_)[0]
    line = first.line if len({p.line for p in short + long_}) == 1 else None
    return line, text + ": " + ", or ".join(parts)
