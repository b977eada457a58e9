"""Seeded random closed layouts from the NXP Cup pieces: :func:`random_layout`.

The result is layout text (docs/layout-format.md) a person can read and edit, valid for the
given car (every check of ``trackgen validate``, the mesh check included); the same seed
and options give the same text. Randomness comes only from ``numpy.random.default_rng(seed)``.

How a layout is drawn (docs/random-tracks.md states the distribution):

1. ``START_FINISH`` at the origin, heading +x (the layout's start pose).
2. The number of crossings ``k`` is uniform in ``crossings``; the route visits k new
   ``CROSSROADS`` (first passes) and then crosses each of them a second time along its side
   road, in a random order and a random direction, each pass between two ``STRAIGHT_SHORT``
   (:data:`LEAD_IN_M`). Between two of these events, and before
   the closing, comes a *walk* of ``walk_pieces`` (uniform) pieces drawn by ``mix``: a
   straight (``STRAIGHT`` or ``STRAIGHT_SHORT``), a turn (left/right, angle from
   ``angles_deg``, radius from ``radii_m``, uniform) or a chicane (left/right).
3. A second pass is reached exactly: a shortest turn-straight-turn path
   (:mod:`trackgen.dubins`, radius drawn from ``radii_m``) to a ``STRAIGHT_SHORT`` lead-in
   before the side port. The last walk is closed the same way onto the start pose. The
   closing turns and straights carry 10 decimals (the loop then closes to ~1e-10 m).
4. The candidate is parsed, chained and validated; a candidate that fails (overlapping
   pieces, a length outside ``length_m``, a closing arc under ``MIN_ARC_DEG`` or a closing
   straight under ``MIN_STRAIGHT_M``) is dropped and the same generator draws the next one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import Mapping

import numpy as np
import shapely
from shapely import affinity

from pieces.library import make_piece
from pieces.pose import Pose2
from pieces.spec import PieceType, TrackSettings
from vehicle.description import CarDescription

from .chain import chain
from .dubins import csc_paths
from .errors import TrackError
from .layout import parse_layout
from .export import track_geometry
from .validate import OVERLAP_TOL_M2, check_meshes, errors, validate_track

MIN_ARC_DEG = 3.0
"""A closing arc shorter than this (and not zero) makes the candidate redrawn."""
MIN_STRAIGHT_M = 0.05
"""A closing straight shorter than this (and not zero) makes the candidate redrawn."""
LEAD_IN_M = 0.5
"""Straight (``STRAIGHT_SHORT``) before each pass of a crossroads, and after it: the kit's
intersection has lined stubs on its four arms (the rules summary, "Intersection": "Short lined
stubs lead into it"), so a car never turns into or out of the open square."""
SEGMENT_TRIES = 20
"""Draws of one walk-and-close segment before the whole candidate is redrawn."""
_ZERO = 1e-9
_DIGITS = 10

DEFAULT_MIX: Mapping[str, float] = MappingProxyType({"straight": 3.0, "turn": 4.0, "chicane": 1.0})
MIX_KINDS = ("straight", "turn", "chicane")


class RandomTrackError(TrackError):
    """Bad options for :func:`random_layout`, or no valid layout within ``max_attempts``."""


@dataclass(frozen=True)
class RandomOptions:
    """What :func:`random_layout` draws from (keyword options of the same names).

    ``length_m``: (min, max) lap length, m. ``crossings``: (min, max) crossroads crossed
    twice (an int n means (n, n)). ``mix``: relative weights of walk pieces ``straight``,
    ``turn``, ``chicane``. ``angles_deg`` / ``radii_m``: the turns' angles (0-180 deg) and
    centreline radii (m; those tighter than the car's minimum turning radius are dropped).
    ``walk_pieces``: (min, max) pieces per walk. ``meshes``: also run the watertight-mesh
    check of ``trackgen validate`` on the emitted layout (~40 ms; the other checks always
    run; bench/bench_random.py runs the full validation over 10,000 seeds).
    ``max_attempts``: candidates tried before giving up.
    """

    length_m: tuple[float, float] = (8.0, 40.0)
    crossings: tuple[int, int] = (0, 2)
    mix: Mapping[str, float] = field(default_factory=lambda: DEFAULT_MIX)
    angles_deg: tuple[float, ...] = (30.0, 45.0, 60.0, 90.0)
    radii_m: tuple[float, ...] = (0.6, 0.8, 1.0)
    walk_pieces: tuple[int, int] = (2, 6)
    meshes: bool = False
    max_attempts: int = 2000

    def __post_init__(self) -> None:
        if isinstance(self.crossings, (int, np.integer)) and not isinstance(self.crossings, bool):
            object.__setattr__(self, "crossings", (int(self.crossings), int(self.crossings)))
        lo, hi = _pair(self, "length_m", float)
        if not 0.0 < lo <= hi:
            raise RandomTrackError(f"length_m = {self.length_m!r}: expected 0 < min <= max (m)")
        lo, hi = _pair(self, "crossings", int)
        if not 0 <= lo <= hi <= 8:
            raise RandomTrackError(f"crossings = {self.crossings!r}: expected 0 <= min <= max <= 8")
        lo, hi = _pair(self, "walk_pieces", int)
        if not 0 <= lo <= hi <= 100:
            raise RandomTrackError(f"walk_pieces = {self.walk_pieces!r}: expected 0 <= min <= max <= 100")
        mix = dict(self.mix)
        unknown = sorted(set(mix) - set(MIX_KINDS))
        if unknown:
            raise RandomTrackError(f"mix: unknown kind {unknown[0]!r} (expected {', '.join(MIX_KINDS)})")
        weights = [float(mix.get(k, 0.0)) for k in MIX_KINDS]
        if any(not math.isfinite(w) or w < 0 for w in weights) or sum(weights) <= 0:
            raise RandomTrackError(f"mix = {mix!r}: expected weights >= 0, not all 0")
        object.__setattr__(self, "mix", MappingProxyType(dict(zip(MIX_KINDS, weights))))
        angles = tuple(float(a) for a in self.angles_deg)
        if not angles or any(not 0.0 < a <= 180.0 for a in angles):
            raise RandomTrackError(f"angles_deg = {self.angles_deg!r}: expected angles in (0, 180]")
        object.__setattr__(self, "angles_deg", angles)
        radii = tuple(float(r) for r in self.radii_m)
        if not radii or any(not (math.isfinite(r) and r > 0.0) for r in radii):
            raise RandomTrackError(f"radii_m = {self.radii_m!r}: expected radii > 0 (m)")
        object.__setattr__(self, "radii_m", radii)
        if int(self.max_attempts) < 1:
            raise RandomTrackError(f"max_attempts = {self.max_attempts!r}: expected >= 1")


def _pair(opts: RandomOptions, name: str, kind: type) -> tuple:
    value = getattr(opts, name)
    try:
        lo, hi = value
        pair = (kind(lo), kind(hi))
    except (TypeError, ValueError):
        raise RandomTrackError(f"{name} = {value!r}: expected (min, max)") from None
    object.__setattr__(opts, name, pair)
    return pair


def _num(value: float) -> str:
    text = f"{value:.{_DIGITS}f}".rstrip("0").rstrip(".")
    return "0" if text in ("", "-0") else text


class _Walker:
    """Builds one candidate: the layout lines, the pose and length they reach, and the road
    footprints placed so far (to redraw a segment that overlaps earlier pieces at once)."""

    def __init__(self, settings: TrackSettings, cache: dict):
        self.settings = settings
        self.pose = Pose2()
        self.length_m = 0.0
        self.lines: list[str] = []
        self.feet: list = []          # world road footprint of each physical piece
        self.order: list[int] = []    # physical piece of each pass, in driving order
        self._cache = cache           # (kind, kwargs) -> Piece, shared by the candidates

    def snapshot(self) -> tuple:
        return self.pose, self.length_m, len(self.lines), len(self.feet), len(self.order)

    def restore(self, snap: tuple) -> None:
        self.pose, self.length_m, n_lines, n_feet, n_order = snap
        del self.lines[n_lines:], self.feet[n_feet:], self.order[n_order:]

    def add(self, kind: PieceType, text_params: str = "", **kwargs: float):
        key = (kind, tuple(sorted(kwargs.items())))
        piece = self._cache.get(key)
        if piece is None:
            piece = self._cache[key] = make_piece(kind, self.settings, **kwargs)
        world = self.pose @ piece.entry.inverse()
        self.pose = world @ piece.exit
        self.length_m += piece.length_m
        self.lines.append(f"{kind.name} {text_params}".rstrip())
        self.order.append(len(self.feet))
        self.feet.append(affinity.affine_transform(piece.footprint, world.as_shapely_affine()))
        return world, piece

    def revisit(self, physical: int, leave: Pose2, length_m: float) -> None:
        """The second pass of crossroads ``physical``, leaving at ``leave``."""
        self.lines.append("CROSSROADS          # second pass")
        self.order.append(physical)
        self.pose = leave
        self.length_m += length_m  # the side road, as the chain counts it

    def clashes(self, since: tuple, closing: bool = False) -> bool:
        """Whether a piece placed after ``since`` overlaps a non-adjacent piece (the test of
        :mod:`trackgen.validate`, OVERLAP_TOL_M2); ``closing``: the loop is complete."""
        first = since[3]
        if first >= len(self.feet):
            return False
        order = self.order + ([self.order[0]] if closing else [])
        adjacent = {(min(a, b), max(a, b)) for a, b in zip(order, order[1:])}
        feet = np.asarray(self.feet, dtype=object)
        for i in range(first, len(self.feet)):
            others = np.array([j for j in range(i) if (j, i) not in adjacent], dtype=int)
            if others.size == 0:
                continue
            hit = others[shapely.intersects(feet[others], feet[i])]
            if hit.size and float(shapely.area(shapely.intersection(feet[hit], feet[i])).max()) > OVERLAP_TOL_M2:
                return True
        return False

    def turn(self, left: bool, angle_deg: float, radius_m: float, exact: bool = False) -> None:
        """A turn, placed analytically (building the piece costs ~1 ms; the closing turns
        are all different): its exit pose and a sampled annular-sector road footprint."""
        text = _num(angle_deg) if exact else f"{angle_deg:g}"
        kind = PieceType.TURN_LEFT if left else PieceType.TURN_RIGHT
        a, r, side = math.radians(float(text)), radius_m, (1.0 if left else -1.0)
        half = 0.5 * self.settings.road_width_m
        t = np.linspace(0.0, a, max(2, int(math.ceil(a / math.radians(5.0))) + 1))
        outer = np.column_stack([(r + half) * np.sin(t), side * (r - (r + half) * np.cos(t))])
        inner = np.column_stack([(r - half) * np.sin(t), side * (r - (r - half) * np.cos(t))])
        foot = shapely.Polygon(np.vstack([outer, inner[::-1]]))
        world = self.pose
        self.pose = world @ Pose2(r * math.sin(a), side * r * (1.0 - math.cos(a)), side * a)
        self.length_m += r * a
        self.lines.append(f"{kind.name} angle={text} radius={radius_m:g}")
        self.order.append(len(self.feet))
        self.feet.append(affinity.affine_transform(foot, world.as_shapely_affine()))

    def straight(self, length_m: float) -> None:
        """A closing straight of exact length, placed analytically like :meth:`turn`."""
        text = _num(length_m)
        length, half = float(text), 0.5 * self.settings.road_width_m
        world = self.pose
        self.pose = world @ Pose2(length, 0.0, 0.0)
        self.length_m += length
        self.lines.append(f"STRAIGHT length={text}")
        self.order.append(len(self.feet))
        self.feet.append(affinity.affine_transform(shapely.box(0.0, -half, length, half),
                                                   world.as_shapely_affine()))


def _walk(rng: np.random.Generator, w: _Walker, opts: RandomOptions, radii: tuple[float, ...],
          chicanes: bool) -> None:
    lo, hi = opts.walk_pieces
    weights = np.array([opts.mix[k] for k in MIX_KINDS])
    if not chicanes:
        weights[2] = 0.0
    if weights.sum() <= 0:
        weights = np.array([1.0, 0.0, 0.0])
    p = weights / weights.sum()
    for _ in range(int(rng.integers(lo, hi + 1))):
        kind = MIX_KINDS[int(rng.choice(3, p=p))]
        if kind == "straight":
            if rng.random() < 0.5:
                w.add(PieceType.STRAIGHT)
            else:
                w.add(PieceType.STRAIGHT_SHORT)
        elif kind == "turn":
            left = bool(rng.random() < 0.5)
            angle = opts.angles_deg[int(rng.integers(len(opts.angles_deg)))]
            radius = radii[int(rng.integers(len(radii)))]
            w.turn(left, angle, radius)
        else:
            w.add(PieceType.CHICANE_LEFT if rng.random() < 0.5 else PieceType.CHICANE_RIGHT)


def _close(rng: np.random.Generator, w: _Walker, goal: Pose2, radii: tuple[float, ...],
           since: tuple, closing: bool) -> bool:
    """Append the shortest turn-straight-turn path to ``goal`` that keeps clear of earlier
    pieces (checked from ``since``); False (nothing appended) if there is none."""
    radius = radii[int(rng.integers(len(radii)))]
    for path in csc_paths(w.pose, goal, radius):
        arcs = [math.degrees(a) for a in (path.arc1_rad, path.arc2_rad)]
        if any(_ZERO < a < MIN_ARC_DEG or a > 360.0 - _ZERO for a in arcs):
            continue
        if _ZERO < path.straight_m < MIN_STRAIGHT_M:
            continue
        snap = w.snapshot()
        for turn, arc in ((path.turn1, arcs[0]), (None, None), (path.turn2, arcs[1])):
            if turn is None:
                if path.straight_m > _ZERO:
                    w.straight(path.straight_m)
                continue
            if arc <= _ZERO:
                continue
            parts = 2 if arc > 180.0 else 1
            for _ in range(parts):
                w.turn(turn > 0, arc / parts, radius, exact=True)
        if not closing:
            w.add(PieceType.STRAIGHT_SHORT)    # the lead-in to a second pass
        if not w.clashes(since, closing):
            return True
        w.restore(snap)
    return False


def _segment(rng: np.random.Generator, w: _Walker, opts: RandomOptions, radii, chicanes: bool,
             goal: Pose2 | None, closing: bool = False) -> bool:
    """A walk, then (``goal`` given) the exact path to ``goal``; a segment that overlaps
    earlier pieces or runs past the longest lap is redrawn up to SEGMENT_TRIES times."""
    since = w.snapshot()
    for _ in range(SEGMENT_TRIES):
        _walk(rng, w, opts, radii, chicanes)
        if w.length_m <= opts.length_m[1] and not w.clashes(since):
            if goal is None or _close(rng, w, goal, radii, since, closing):
                if w.length_m <= opts.length_m[1]:
                    return True
        w.restore(since)
    return False


def _candidate(rng: np.random.Generator, opts: RandomOptions, settings: TrackSettings,
               radii: tuple[float, ...], chicanes: bool, cache: dict) -> _Walker | None:
    w = _Walker(settings, cache)
    w.add(PieceType.START_FINISH)
    k = int(rng.integers(opts.crossings[0], opts.crossings[1] + 1))
    ports: list[tuple[int, Pose2, Pose2, float]] = []  # physical index, side_in, side_out, length
    for _ in range(k):
        if not _segment(rng, w, opts, radii, chicanes, None):
            return None
        since = w.snapshot()
        w.add(PieceType.STRAIGHT_SHORT)              # the lead-in
        world, piece = w.add(PieceType.CROSSROADS)
        w.add(PieceType.STRAIGHT_SHORT)              # the lead-out
        if w.clashes(since):
            return None
        ports.append((len(w.feet) - 1, world @ piece.ports["side_in"],
                      world @ piece.ports["side_out"], piece.length_m))
    for i in rng.permutation(k):
        physical, side_in, side_out, side_m = ports[int(i)]
        if rng.random() < 0.5:
            port, leave = side_in, side_out
        else:
            port, leave = side_out.reversed(), side_in.reversed()
        if not _segment(rng, w, opts, radii, chicanes, port @ Pose2(-LEAD_IN_M, 0.0, 0.0)):
            return None
        w.revisit(physical, leave, side_m)
        since = w.snapshot()
        w.add(PieceType.STRAIGHT_SHORT)              # the lead-out
        if w.clashes(since):
            return None
    if not _segment(rng, w, opts, radii, chicanes, Pose2(), closing=True):
        return None
    return w


def _collapse(lines: list[str]) -> list[str]:
    """Consecutive identical pieces as one ``xN`` line."""
    out: list[tuple[str, int]] = []
    for line in lines:
        if out and out[-1][0] == line and "#" not in line:
            out[-1] = (line, out[-1][1] + 1)
        else:
            out.append((line, 1))
    return [line if n == 1 else f"{line} x{n}" for line, n in out]


def random_layout(seed: int, *, car: CarDescription | None = None, **options) -> str:
    """Layout text of a random closed track, valid for ``car`` (default: the built-in car).

    ``seed``: a whole number >= 0; the same seed and options give the same text.
    ``options``: the fields of :class:`RandomOptions` (``length_m=(10, 30)``,
    ``crossings=(0, 2)``, ``mix={"straight": 3, "turn": 4, "chicane": 1}``, ...).
    Raises :class:`RandomTrackError` for bad options or when ``max_attempts`` candidates
    all fail.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise RandomTrackError(f"seed = {seed!r}: expected a whole number >= 0")
    known = {f.name for f in fields(RandomOptions)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise RandomTrackError(f"unknown option {unknown[0]!r} (expected one of {', '.join(sorted(known))})")
    opts = RandomOptions(**options)
    car = car or CarDescription()
    settings = TrackSettings()
    min_r = car.min_turn_radius_m
    radii = tuple(r for r in opts.radii_m if r >= min_r and r > settings.road_width_m / 2)
    if not radii:
        raise RandomTrackError(f"radii_m = {opts.radii_m!r}: none is at least the car's minimum "
                               f"turning radius {min_r:.3f} m")
    chicanes = make_piece(PieceType.CHICANE_LEFT, settings).min_radius_m >= min_r
    rng = np.random.default_rng(int(seed))
    name = f"random_{int(seed)}"
    cache: dict = {}
    for attempt in range(1, int(opts.max_attempts) + 1):
        w = _candidate(rng, opts, settings, radii, chicanes, cache)
        if w is None or not opts.length_m[0] <= w.length_m <= opts.length_m[1]:
            continue
        crossings = sum(1 for line in w.lines if line.startswith("CROSSROADS") and "#" in line)
        text = "\n".join([
            f"# Random NXP Cup track: trackgen random --seed {int(seed)} (attempt {attempt})",
            f"# {crossings} crossroads crossed twice, lap {w.length_m:.2f} m; closing pieces "
            "carry 10 decimals so the loop closes exactly",
            f"@name = {name}", "", *_collapse(w.lines), ""])
        layout = parse_layout(text, path=f"<random seed {int(seed)}>", default_name=name)
        if name == car.name:  # pragma: no cover - car names are not random_N
            continue
        track = chain(layout)
        if errors(validate_track(track, min_r)):
            continue
        if not opts.meshes or not check_meshes(track_geometry(track).meshes):
            return text
    raise RandomTrackError(f"seed {int(seed)}: no valid layout in {opts.max_attempts} attempts "
                           "(widen length_m, lower crossings or walk_pieces)")


__all__ = ["random_layout", "RandomOptions", "RandomTrackError", "DEFAULT_MIX"]
