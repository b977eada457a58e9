"""Piece kinds, track-wide settings and the parameter table a layout file can set.

Everything a person can type for a piece is described once here, in the units a person
types (metres, degrees), together with the keyword argument it becomes in the Python API
(metres, radians). ``trackgen`` uses :data:`PARAMS` to report unknown or out-of-range
parameters by name; :func:`pieces.piece_from_layout` uses it to convert.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, fields
from types import MappingProxyType
from typing import Callable, Mapping


class PieceError(ValueError):
    """A bad piece parameter or setting; the message names it, its value and the range."""


class PieceType(enum.Enum):
    """The six NXP Cup piece types of the thesis (turns and chicanes in two hands), and the
    official kit's extender (a short straight: :data:`KITS`)."""

    STRAIGHT = "STRAIGHT"
    STRAIGHT_SHORT = "STRAIGHT_SHORT"
    CROSSROADS = "CROSSROADS"
    TURN_LEFT = "TURN_LEFT"
    TURN_RIGHT = "TURN_RIGHT"
    CHICANE_LEFT = "CHICANE_LEFT"
    CHICANE_RIGHT = "CHICANE_RIGHT"
    START_FINISH = "START_FINISH"
    EXTENDER = "EXTENDER"
    SPEED_LIMIT_START = "SPEED_LIMIT_START"
    SPEED_LIMIT_END = "SPEED_LIMIT_END"
    WAVE = "WAVE"
    TUNNEL = "TUNNEL"
    HILL = "HILL"


def _identity(value: float) -> float:
    return float(value)


@dataclass(frozen=True)
class ParamSpec:
    """One settable number.

    ``name`` is the layout-file name (``angle``), ``unit`` the unit a person types
    (``"m"`` or ``"deg"``), ``default``/``lo``/``hi`` are in that unit; ``lo_open`` /
    ``hi_open`` say whether the bound itself is excluded. ``internal`` is the Python
    keyword it becomes (``angle_rad``) and ``to_internal`` converts the typed value.
    """

    name: str
    unit: str
    default: float
    lo: float
    hi: float = math.inf
    lo_open: bool = True
    hi_open: bool = False
    internal: str = ""
    to_internal: Callable[[float], float] = _identity

    def range_text(self) -> str:
        """Human-readable range, e.g. ``(0, 180] deg``."""
        left = "(" if self.lo_open else "["
        right = ")" if (self.hi_open or math.isinf(self.hi)) else "]"
        hi = "inf" if math.isinf(self.hi) else f"{self.hi:g}"
        return f"{left}{self.lo:g}, {hi}{right} {self.unit}"

    def contains(self, value: float) -> bool:
        """True if ``value`` (typed units) is finite and inside the range."""
        if not math.isfinite(value):
            return False
        lo_ok = value > self.lo if self.lo_open else value >= self.lo
        hi_ok = value < self.hi if self.hi_open else value <= self.hi
        return lo_ok and hi_ok

    def check(self, value: float) -> float:
        """Validate a typed value; return it converted to internal units."""
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise PieceError(f"{self.name}={value!r}: expected a number in {self.range_text()}") from None
        if not self.contains(value):
            raise PieceError(f"{self.name}={value:g} {self.unit}: expected {self.range_text()}")
        return self.to_internal(value)


def check_range(name: str, value: float, lo: float, hi: float = math.inf, *,
                unit: str = "m", lo_open: bool = True, hi_open: bool = False,
                why: str = "") -> float:
    """Validate an internal-unit value; raise :class:`PieceError` naming ``name`` (and
    ``why`` the range is what it is, if given)."""
    try:
        return ParamSpec(name, unit, value, lo, hi, lo_open, hi_open).check(value)
    except PieceError as err:
        if why:
            raise PieceError(f"{err} ({why})") from None
        raise


MIN_LENGTH_M, MAX_LENGTH_M = 0.001, 100.0
"""Range of every piece length, radius and offset a layout can type (before ``@scale``):
1 mm to 100 m -- bounds that keep every piece's geometry finite and its meshing bounded."""


def _m(name: str, default: float, lo: float = MIN_LENGTH_M, hi: float = MAX_LENGTH_M,
       **kw) -> ParamSpec:
    kw.setdefault("lo_open", False)
    return ParamSpec(name, "m", default, lo, hi, internal=f"{name}_m", **kw)


_ANGLE = ParamSpec("angle", "deg", 45.0, 0.001, 180.0, lo_open=False, internal="angle_rad",
                   to_internal=math.radians)

#: Layout-file parameters per kind: ``PARAMS[kind][layout_name] -> ParamSpec``.
PARAMS: Mapping[PieceType, Mapping[str, ParamSpec]] = MappingProxyType({
    PieceType.STRAIGHT: MappingProxyType({"length": _m("length", 1.0)}),
    PieceType.STRAIGHT_SHORT: MappingProxyType({"length": _m("length", 0.5)}),
    PieceType.CROSSROADS: MappingProxyType({
        "length": _m("length", 0.6),  # at 90 deg; at other angles the smallest that fits
        "angle": ParamSpec("angle", "deg", 90.0, 30.0, 150.0, lo_open=False, internal="angle_rad",
                           to_internal=math.radians)}),
    PieceType.TURN_LEFT: MappingProxyType({"radius": _m("radius", 0.8), "angle": _ANGLE}),
    PieceType.TURN_RIGHT: MappingProxyType({"radius": _m("radius", 0.8), "angle": _ANGLE}),
    PieceType.CHICANE_LEFT: MappingProxyType({"length": _m("length", 1.0), "offset": _m("offset", 0.2)}),
    PieceType.CHICANE_RIGHT: MappingProxyType({"length": _m("length", 1.0), "offset": _m("offset", 0.2)}),
    PieceType.START_FINISH: MappingProxyType({"length": _m("length", 1.0),
                                              "mark_length": _m("mark_length", 0.05),
                                              "mark_gap": _m("mark_gap", 0.0, 0.0),
                                              "mark_inset": _m("mark_inset", 0.0, 0.0),
                                              "mark_offset": _m("mark_offset", 0.0, -MAX_LENGTH_M)}),
    PieceType.EXTENDER: MappingProxyType({"length": _m("length", 0.17)}),
    # the rules' speed-limit pieces: 4 (start) or 3 (end) stripes along the lane, 0.30 x 0.05 m
    # with 0.05 m gaps, centred (../shared/reference/nxp-cup-rules.md, section 1.2)
    PieceType.SPEED_LIMIT_START: MappingProxyType({"length": _m("length", 0.72),
                                                   "stripe_length": _m("stripe_length", 0.30),
                                                   "stripe_width": _m("stripe_width", 0.05)}),
    # the rules' chicane: two waves of R400 arcs, the lane swinging 85.57 mm side to side
    # (envelope 635.57 of a 550 road; ../shared/reference/nxp-cup-rules.md, section 1.2)
    PieceType.WAVE: MappingProxyType({"length": _m("length", 1.44), "swing": _m("swing", 0.08557)}),
    # a straight under a roof: TRANSMISSION of the light reaches its floor (ours: 0.15, the
    # light under a covered section of a hall; 2018/19 tracks "can have" tunnels, rules
    # summary section 1.1)
    PieceType.TUNNEL: MappingProxyType({"length": _m("length", 1.0),
                                        "transmission": ParamSpec("transmission", "", 0.15, 0.0, 1.0,
                                                                  lo_open=False, internal="transmission")}),
    # a straight lifted by a raised-cosine hill HEIGHT high at its middle (worlds.terrain); the
    # rules allow inclines and declines (2018/19) without sizes (rules summary section 1.1): ours,
    # two kit straights long, a 12-degree steepest slope
    PieceType.HILL: MappingProxyType({"length": _m("length", 1.44), "height": _m("height", 0.10)}),
    PieceType.SPEED_LIMIT_END: MappingProxyType({"length": _m("length", 0.72),
                                                 "stripe_length": _m("stripe_length", 0.30),
                                                 "stripe_width": _m("stripe_width", 0.05)}),
})


@dataclass(frozen=True)
class Kit:
    """A track kit: the defaults a layout's ``@kit = NAME`` puts in place of the pieces' own
    (layout names and units, as :data:`PARAMS`) and of the track-wide settings; a value
    the layout gives still wins. ``source``: where the numbers come from."""

    name: str
    params: Mapping[PieceType, Mapping[str, float]]
    settings: Mapping[str, float]
    source: str


_RULES = "../shared/reference/nxp-cup-rules.md, section 1.2 (the track kit's drawings, TC)"
_KIT_TURN = MappingProxyType({"radius": 0.445, "angle": 45.0})  # R170 / R720 edges: lane centre R445
#: The kits a layout can name with ``@kit``.
KITS: Mapping[str, Kit] = MappingProxyType({
    "nxp": Kit("nxp", MappingProxyType({
        PieceType.STRAIGHT: MappingProxyType({"length": 0.72}),
        PieceType.EXTENDER: MappingProxyType({"length": 0.17}),
        PieceType.CROSSROADS: MappingProxyType({"length": 0.55}),  # the 550 x 550 square (its stubs: EXTENDERs)
        PieceType.TURN_LEFT: _KIT_TURN,
        PieceType.TURN_RIGHT: _KIT_TURN,
        # two 20 x 94 mm bars, a 74 mm gap in the lane's centre, 124 mm of white to each line,
        # their near edge 550 mm from the piece's entry (the rules do not say which end: ours)
        PieceType.START_FINISH: MappingProxyType({"length": 0.72, "mark_length": 0.02, "mark_gap": 0.074,
                                                  "mark_inset": 0.124, "mark_offset": 0.20}),
    }), MappingProxyType({"lane_width": 0.51, "edge_width": 0.02}),  # 550 over the lines, 20 mm lines inside
        _RULES),
})

#: Track-wide settings a layout file can set: layout name -> ParamSpec (internal = field name).
#: Ranges hold for the values typed and for the values after ``@scale``.
SETTINGS_PARAMS: Mapping[str, ParamSpec] = MappingProxyType({
    "lane_width": _m("lane_width", 0.55, 1e-4, 100.0),
    "edge_width": _m("edge_width", 0.020, 1e-5, 10.0),
    "thickness": _m("thickness", 0.01, 1e-6, 10.0),
    "arc_tolerance": _m("arc_tolerance", 0.001, 1e-5, 0.05),
})


@dataclass(frozen=True)
class TrackSettings:
    """Track-wide dimensions, metres.

    ``lane_width_m``: white lane, edge to edge (between the black lines).
    ``edge_width_m``: each black edge line, laid OUTSIDE the lane (road = lane + 2 edges).
    ``thickness_m``: slab height; meshes span z in [0, thickness_m].
    ``arc_tolerance_m``: max sagitta between a true arc and its polyline, in [1e-5, 0.05].
    Ranges: :data:`SETTINGS_PARAMS`.
    """

    lane_width_m: float = 0.55
    edge_width_m: float = 0.020
    thickness_m: float = 0.01
    arc_tolerance_m: float = 0.001

    def __post_init__(self) -> None:
        for f in fields(self):
            spec = SETTINGS_PARAMS[f.name.removesuffix("_m")]
            value = check_range(f.name, getattr(self, f.name), spec.lo, spec.hi,
                                lo_open=spec.lo_open)
            object.__setattr__(self, f.name, value)

    @property
    def road_width_m(self) -> float:
        """Lane plus both edge lines."""
        return self.lane_width_m + 2.0 * self.edge_width_m

    @classmethod
    def from_layout(cls, values: Mapping[str, float]) -> "TrackSettings":
        """Build from layout names (``lane_width=0.55``); unknown names raise PieceError."""
        kwargs = {}
        for name, value in values.items():
            if name not in SETTINGS_PARAMS:
                known = ", ".join(SETTINGS_PARAMS)
                raise PieceError(f"unknown track setting {name!r}: expected one of {known}")
            kwargs[SETTINGS_PARAMS[name].internal] = SETTINGS_PARAMS[name].check(value)
        return cls(**kwargs)
