"""Layout files: the text a person writes to describe a track, one piece per line.

Format (UTF-8 text; see also docs/layout-format.md)::

    # The thesis's figure 8 (Figure 4.2)        <- '#' starts a comment, anywhere on a line
    @name = thesis_figure8                        <- track-wide setting: '@key = value'
    @lane_width = 0.55
    CROSSROADS
    STRAIGHT_SHORT
    TURN_LEFT x2                                  <- 'xN' repeats the piece N times
    STRAIGHT length=1.2                           <- 'key=value' piece parameters
    TURN_LEFT angle=90 radius=0.6   # degrees, metres

Pieces (names are case-insensitive) and their parameters, in the units people type
(lengths in metres, angles in degrees; defaults from ``pieces.PARAMS``):

    STRAIGHT        length=1.0
    STRAIGHT_SHORT  length=0.5
    CROSSROADS      length=0.6          (crossed a second time: see trackgen.chain)
    TURN_LEFT       radius=0.8 angle=45
    TURN_RIGHT      radius=0.8 angle=45
    CHICANE_LEFT    length=1.0 offset=0.2
    CHICANE_RIGHT   length=1.0 offset=0.2
    START_FINISH    length=1.0 mark_length=0.05 mark_offset=0 mark_gap=0 mark_inset=0
    EXTENDER        length=0.17
    SPEED_LIMIT_START length=0.72 stripe_length=0.30 stripe_width=0.05   (4 stripes; _END: 3)
    WAVE            length=1.44 swing=0.08557

Track-wide settings, each at most once, anywhere in the file (conventionally at the top):

    @name = TEXT          model/track name: letters, digits, '_', '-', '.' (default: file stem)
    @kit = nxp            the official kit's pieces and road as the defaults (pieces.KITS)
    @lane_width = 0.55    white lane width, m
    @edge_width = 0.02    each black edge line, m (laid outside the lane)
    @thickness = 0.01     slab height of the meshes, m
    @arc_tolerance = 0.001  max chord error of curved edges, m (not scaled)
    @scale = 1.0          (0.01 .. 100) multiplies every length above and every piece
                          length/radius/offset, given or default (angles are not scaled;
                          1.3 gives the thesis's 130 % Gazebo track): a scaled layout is the
                          unscaled one scaled, and closes exactly when that one does

Light and surfaces (the physical camera's scene; ``worlds.lighting``, docs/camera.md):

    @ambient_lux = 500    illuminance on the whole track, lux (0 .. 200000)
    @light = X Y Z INTENSITY_CD [CONE_DEG]   a lamp at world X Y Z (m; Z above the track,
                          scaled by @scale), luminous intensity in candela, optionally a spot
                          pointing down with that full cone angle (deg); may repeat
    @shade = X Y LENGTH WIDTH HEADING_DEG TRANSMISSION   a tunnel's roof or a shadow: the
                          LENGTH x WIDTH rectangle (m, scaled by @scale) centred at world X Y,
                          its length along HEADING_DEG, lets through TRANSMISSION (0 .. 1) of
                          the light; may repeat
    @lane_reflectance = 0.92, @line_reflectance = 0.06, @floor_reflectance = 0.16,
    @specular = 0.03      fractions of light the lane, the black lines and the floor return;
                          the glossy share of the lamps' light

Printed marks (``worlds.marks``, docs/pixy2.md):

    @barcode = X Y CODE HEADING_DEG [MODULE [LENGTH]]   a Pixy2 barcode CODE (0 .. 15) on a
                          white card centred at world X Y (m), its bars along HEADING_DEG (the
                          direction a car drives over it), narrow bar MODULE m wide (0.01), bars
                          LENGTH m long (0.05); lengths scaled by @scale; may repeat

Objects standing on the track (``worlds.solids``, docs/events.md):

    @box = X Y LENGTH WIDTH HEIGHT [HEADING_DEG [REFLECTANCE]]   a box centred at world X Y
                          (m), LENGTH along HEADING_DEG (0), WIDTH across, HEIGHT tall,
                          returning REFLECTANCE of the light (0.85: white polystyrene); the
                          car must not touch it; lengths scaled by @scale; may repeat

Limits: a repeat count is 1..MAX_REPEAT, a layout has at most MAX_PIECES pieces after
repeats and at most MAX_FILE_BYTES bytes, a line (without its comment) at most
MAX_LINE_CHARS characters, a number at most MAX_NUMBER_CHARS; every number has a range
(``pieces.PARAMS``, ``pieces.SETTINGS_PARAMS``). Piece names, parameter names and settings
are ASCII (``ſtraight`` is not ``STRAIGHT``). Every error is a :class:`LayoutError` whose
``str`` is ``path:line: message``, e.g.
``track.txt:7: unknown piece 'TRUN_LEFT' (expected one of STRAIGHT, ...; did you mean TURN_LEFT?)``.
"""
from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

from pieces.spec import KITS, PARAMS, SETTINGS_PARAMS, ParamSpec, PieceError, PieceType, TrackSettings

from worlds.lighting import LIMITS as LIGHT_LIMITS
from worlds.lighting import Light, Shade, TrackLighting
from worlds.marks import DEFAULT_LENGTH_M, DEFAULT_MODULE_M, Barcode
from worlds.marks import LIMITS as MARK_LIMITS
from worlds.solids import LIMITS as SOLID_LIMITS, WHITE_REFLECTANCE, Solid, box_mass_kg

from .errors import LayoutError

MAX_REPEAT = 1000
"""Largest ``xN`` repeat count on one line."""
MAX_PIECES = 10_000
"""Largest number of pieces in one layout, after expanding repeats."""
MAX_FILE_BYTES = 4 * 1024 * 1024
"""Largest layout file read (a 10 000-piece layout is ~200 kB)."""
MIN_SCALE, MAX_SCALE = 0.01, 100.0
"""``@scale`` must lie in [MIN_SCALE, MAX_SCALE]."""
MAX_LINE_CHARS = 1000
"""Longest line, without its comment (a piece line is ~40 characters)."""
MAX_NUMBER_CHARS = 40
"""Longest number (``0.000000000000000000000000000000001`` fits)."""

PIECE_NAMES: tuple[str, ...] = tuple(k.name for k in PieceType)
SCALED_SETTINGS = ("lane_width", "edge_width", "thickness")
"""Settings that ``@scale`` multiplies (``arc_tolerance`` is a meshing accuracy, not a size)."""
LIGHT_SETTINGS = ("ambient_lux", "light", "shade", "lane_reflectance", "line_reflectance",
                  "floor_reflectance", "specular")
"""The light and surface settings (``worlds.lighting.TrackLighting``); ``@light`` and ``@shade`` repeat."""
EXTRA_SETTINGS = ("name", "scale", "kit") + LIGHT_SETTINGS + ("barcode", "box")

# Unambiguous (no nested quantifiers over the same digits): linear time on any input.
_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?\Z", re.ASCII)
_REPEAT = re.compile(r"[xX]([+-]?[0-9.eE+-]*)\Z")
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}\Z", re.ASCII)
_CONTROL_BYTES = re.compile(rb"[\x00-\x08\x0e-\x1f\x7f]")
_CONTROL_CHARS = re.compile("[\x00-\x08\x0e-\x1f\x7f-\x9f\ud800-\udfff]")
"""Unicode categories Cc (except tab, newlines, form feed) and Cs."""


@dataclass(frozen=True)
class LayoutEntry:
    """One piece of a layout: ``kind``, the parameters given on its line (layout names and
    typed units, unscaled, e.g. ``{"angle": 90.0}``) and its 1-based source ``line``."""

    kind: PieceType
    params: Mapping[str, float]
    line: int

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))

    def describe(self) -> str:
        """``TURN_LEFT angle=90`` as it would be written."""
        return " ".join([self.kind.name] + [f"{k}={v:g}" for k, v in self.params.items()])


@dataclass(frozen=True)
class Layout:
    """A parsed layout.

    ``path``: how the source was named (used in every message). ``name``: track name.
    ``scale``: the ``@scale`` factor. ``settings``: :class:`pieces.TrackSettings` with the
    scale already applied. ``setting_values``: the ``@`` settings as typed (layout names,
    unscaled, without name/scale). ``entries``: pieces in driving order, repeats expanded.
    """

    path: str
    name: str
    entries: tuple[LayoutEntry, ...]
    settings: TrackSettings = field(default_factory=TrackSettings)
    scale: float = 1.0
    setting_values: Mapping[str, float] = field(default_factory=dict)
    lighting: TrackLighting = field(default_factory=TrackLighting)  # @ambient_lux, @light, ...
    barcodes: tuple[Barcode, ...] = ()  # @barcode lines (worlds.marks)
    boxes: tuple = ()  # @box lines (worlds.solids.Solid): objects standing on the track
    kit: str | None = None  # @kit: the pieces' defaults come from pieces.KITS[kit]
    # the line of each @ setting set once (name -> line number), for messages about a setting
    setting_lines: Mapping[str, int] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "entries", tuple(self.entries))
        object.__setattr__(self, "setting_values", MappingProxyType(dict(self.setting_values)))
        object.__setattr__(self, "setting_lines", MappingProxyType(dict(self.setting_lines)))

    def piece_kwargs(self, entry: LayoutEntry) -> dict[str, float]:
        """Keywords for ``pieces.make_piece`` (internal units, scale applied). With a scale
        other than 1 every length is given, the defaults scaled too."""
        specs = PARAMS[entry.kind]
        kit = KITS[self.kit].params.get(entry.kind, {}) if self.kit else {}
        out = {}
        for name, spec in specs.items():
            if name in entry.params:
                value = entry.params[name]
            elif (entry.kind is PieceType.CROSSROADS and name == "length"
                  and entry.params.get("angle", 90.0) != 90.0):
                continue  # a crossing at another angle: the smallest length that fits it (the
                # piece's own default, from the scaled road; the kit's is for its square)
            elif name in kit:
                value = kit[name]
            elif spec.unit == "m" and self.scale != 1.0:
                value = spec.default
            else:
                continue
            internal = spec.to_internal(value)
            out[spec.internal] = internal * self.scale if spec.unit == "m" else internal
        return out

    def layout_names(self, message: str, entry: LayoutEntry) -> str:
        """A piece constructor's message in the layout's words: internal keyword names
        (``length_m=0.78``) become layout names (``length=0.78``), with the scale noted."""
        for spec in PARAMS[entry.kind].values():
            message = re.sub(rf"\b{spec.internal}=", f"{spec.name}=", message)
        if self.scale != 1.0:
            message += f" (lengths after @scale = {self.scale:g})"
        return message

    def error(self, line: int | None, message: str) -> LayoutError:
        return LayoutError(self.path, line, message)


def range_text(spec: ParamSpec) -> str:
    """``0.001 <= angle <= 180 (deg)`` / ``length > 0 (m)`` for an error message."""
    lo_op = "<" if spec.lo_open else "<="
    if math.isinf(spec.hi):
        return f"{spec.name} {'>' if spec.lo_open else '>='} {spec.lo:g} ({spec.unit})"
    hi_op = "<" if spec.hi_open else "<="
    return f"{spec.lo:g} {lo_op} {spec.name} {hi_op} {spec.hi:g} ({spec.unit})"


def _did_you_mean(word: str, choices) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f"; did you mean {close[0]}?" if close else ""


def _shown(token: str, limit: int = 40) -> str:
    """A token quoted for a message, shortened and with control characters escaped."""
    text = token if len(token) <= limit else token[: limit - 3] + "..."
    return repr(text)


def _bare(token: str, limit: int = 40) -> str:
    """A token for a message without quotes (``angle=400``), shortened like :func:`_shown`."""
    return _shown(token, limit)[1:-1]


def decode_layout(data: bytes, path: str) -> str:
    """Bytes -> text; non-UTF-8 bytes or control characters raise ``path:line: not a text
    layout file`` at the line of the first offending byte."""
    if len(data) > MAX_FILE_BYTES:
        raise LayoutError(path, 1, f"layout file too large ({len(data)} bytes > {MAX_FILE_BYTES})")
    bad_at, why = len(data), ""
    ctrl = _CONTROL_BYTES.search(data)
    if ctrl:
        bad_at, why = ctrl.start(), f"control byte 0x{data[ctrl.start()]:02x}"
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        if exc.start < bad_at:
            bad_at, why = exc.start, f"byte 0x{data[exc.start]:02x} is not UTF-8"
        text = None
    if text is not None and not why:
        bad = _CONTROL_CHARS.search(text)
        if bad:
            i, ch = bad.start(), bad.group()
            bad_at = len(text[:i].encode("utf-8", "surrogatepass"))
            why = f"control character U+{ord(ch):04X}"
    if why:
        line = data.count(b"\n", 0, bad_at) + 1
        raise LayoutError(path, line, f"not a text layout file ({why})")
    return text


def load_layout(path: str | Path) -> Layout:
    """Read and parse a layout file. Raises :class:`LayoutError` (unreadable: line None)."""
    shown = str(path)
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_FILE_BYTES + 1)
    except IsADirectoryError:
        raise LayoutError(shown, None, "is a folder, expected a layout file") from None
    except OSError as exc:
        raise LayoutError(shown, None, f"cannot read layout ({exc.strerror or exc})") from None
    return parse_layout(decode_layout(data, shown), path=shown, default_name=Path(shown).stem)


def sanitize_name(text: str) -> str:
    """A file stem made into a valid track name (``[A-Za-z0-9_.-]``, <= 64 chars)."""
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", text).lstrip(".-")[:64]
    return name or "track"


def parse_layout(text: str, *, path: str = "<layout>", default_name: str = "track") -> Layout:
    """Parse layout text (see the module docstring). Raises :class:`LayoutError`."""
    entries: list[LayoutEntry] = []
    values: dict[str, float] = {}
    seen_at: dict[str, int] = {}
    name, scale, kit = sanitize_name(default_name), 1.0, None
    light_values: dict[str, float] = {}
    lamps: list[tuple[int, tuple[float, ...]]] = []
    shade_lines: list[tuple[float, ...]] = []
    code_lines: list[tuple[float, ...]] = []
    box_lines: list[tuple[float, ...]] = []
    lines = text.removeprefix("\ufeff").split("\n")
    for lineno, raw in enumerate(lines, start=1):
        body = raw.split("#", 1)[0].strip()
        if not body:
            continue
        if len(body) > MAX_LINE_CHARS:
            raise LayoutError(path, lineno, f"line too long ({len(body)} characters before any "
                                            f"comment; expected at most {MAX_LINE_CHARS}): "
                                            f"{_shown(body)}")
        if body.startswith("@"):
            key, value = _parse_setting(body, path, lineno)
            if key == "light":
                lamps.append((lineno, value))
                continue
            if key == "shade":
                shade_lines.append(value)
                continue
            if key == "barcode":
                code_lines.append(value)
                continue
            if key == "box":
                box_lines.append(value)
                continue
            if key in seen_at:
                raise LayoutError(path, lineno, f"@{key} set twice (first on line {seen_at[key]})")
            seen_at[key] = lineno
            if key == "name":
                name = value
            elif key == "kit":
                kit = value
            elif key == "scale":
                scale = value
            elif key in LIGHT_SETTINGS:
                light_values[key] = value
            else:
                values[key] = value
            continue
        entry, repeat = _parse_piece(body, path, lineno)
        if len(entries) + repeat > MAX_PIECES:
            raise LayoutError(path, lineno, f"too many pieces ({len(entries) + repeat} > "
                                            f"{MAX_PIECES} allowed in one layout)")
        entries.extend([entry] * repeat)
    if not entries:
        raise LayoutError(path, 1, "empty layout: no pieces (expected one piece per line, "
                                   "e.g. STRAIGHT)")
    wanted = dict(values)
    if kit is not None:  # the kit's track-wide settings, unless the layout sets them
        wanted = {**KITS[kit].settings, **values}
    scaled = {k: (v * scale if k in SCALED_SETTINGS else v) for k, v in wanted.items()}
    defaults = TrackSettings()
    for k in SCALED_SETTINGS:
        if k not in scaled and scale != 1.0:
            scaled[k] = getattr(defaults, SETTINGS_PARAMS[k].internal) * scale
    try:
        settings = TrackSettings.from_layout(scaled)
    except PieceError as exc:  # only reachable through extreme scale factors
        line = seen_at.get("scale", 1)
        raise LayoutError(path, line, f"track settings after @scale={scale:g}: {exc}") from None
    lights = tuple(Light(x * scale, y * scale, z * scale, cd, cone) for _, (x, y, z, cd, cone) in lamps)
    shades = tuple(Shade(x * scale, y * scale, length * scale, width * scale, math.radians(heading), t)
                   for x, y, length, width, heading, t in shade_lines)
    lighting = TrackLighting(lights=lights, shades=shades, **light_values)
    barcodes = tuple(Barcode(x * scale, y * scale, int(code), math.radians(heading), module * scale, length * scale)
                     for x, y, code, heading, module, length in code_lines)
    boxes = tuple(Solid(f"box_{i + 1}", x * scale, y * scale, length * scale, width * scale, height * scale,
                        math.radians(heading), reflectance,
                        box_mass_kg(length * scale, width * scale, height * scale))
                  for i, (x, y, length, width, height, heading, reflectance) in enumerate(box_lines))
    return Layout(path=path, name=name, entries=tuple(entries), settings=settings,
                  scale=scale, setting_values=values, lighting=lighting, barcodes=barcodes, kit=kit,
                  boxes=boxes, setting_lines=seen_at)


def _parse_setting(body: str, path: str, lineno: int) -> tuple[str, object]:
    key, sep, value = body[1:].partition("=")
    key, value = key.strip(), value.strip()
    if not sep:  # also accept '@key value'
        key, _, value = body[1:].strip().partition(" ")
        key, value = key.strip(), value.strip()
    key = key.lower()
    known = list(EXTRA_SETTINGS) + list(SETTINGS_PARAMS)
    if key not in known or not key.isascii():
        hint = _did_you_mean(key, known)
        raise LayoutError(path, lineno, f"unknown setting @{_bare(key)} (expected one of "
                                        f"{', '.join('@' + k for k in known)}{hint})")
    if not value:
        raise LayoutError(path, lineno, f"@{key}: missing value (expected '@{key} = VALUE')")
    if key == "light":
        return key, _parse_light(value, path, lineno)
    if key == "shade":
        return key, _parse_shade(value, path, lineno)
    if key == "barcode":
        return key, _parse_barcode(value, path, lineno)
    if key == "box":
        return key, _parse_box(value, path, lineno)
    if key == "kit":
        word = value.lower()
        if word not in KITS or not word.isascii():
            raise LayoutError(path, lineno, f"@kit = {_shown(value)}: expected one of {', '.join(KITS)}"
                                            f"{_did_you_mean(word, list(KITS))}")
        return key, word
    if key == "name":
        if not _NAME.match(value):
            raise LayoutError(path, lineno, f"@name = {_shown(value)}: expected 1-64 letters, "
                                            "digits, '_', '-' or '.' (not starting with '.' or '-')")
        return key, value
    number = _number(value)
    if number is None:
        raise LayoutError(path, lineno, f"@{key} = {_shown(value)}: expected a number")
    if key == "scale":
        if not MIN_SCALE <= number <= MAX_SCALE:
            raise LayoutError(path, lineno, f"@scale = {_bare(value)}: expected {MIN_SCALE:g} "
                                            f"<= scale <= {MAX_SCALE:g}")
        return key, number
    if key in LIGHT_SETTINGS:
        lo, hi = LIGHT_LIMITS["ambient_lux" if key == "ambient_lux" else
                              "specular" if key == "specular" else "reflectance"]
        if not lo <= number <= hi:
            raise LayoutError(path, lineno, f"@{key} = {_bare(value)}: expected {lo:g} <= {key} <= {hi:g}"
                                            f"{' (lux)' if key == 'ambient_lux' else ' (a fraction)'}")
        return key, number
    spec = SETTINGS_PARAMS[key]
    if not spec.contains(number):
        raise LayoutError(path, lineno, f"@{key} = {_bare(value)}: expected {range_text(spec)}")
    return key, number


def _ranged_numbers(key: str, words: list[str], fields: tuple[tuple[str, str], ...], usage: str,
                    path: str, lineno: int, limits=LIGHT_LIMITS) -> list[float]:
    """The numbers of an ``@key`` line's ``words``, each ``(NAME, limit)`` of ``fields`` checked
    against ``limits[limit]`` (``worlds.lighting.LIMITS``)."""
    numbers = []
    for word, (what, limit) in zip(words, fields):
        number = _number(word)
        if number is None:
            raise LayoutError(path, lineno, f"@{key}: {what} = {_shown(word)}: expected a number; {usage}")
        lo, hi = limits[limit]
        if not lo <= number <= hi:
            raise LayoutError(path, lineno, f"@{key}: {what} = {_bare(word)}: expected {lo:g} <= {what} <= {hi:g}")
        numbers.append(number)
    return numbers


def _setting_words(key: str, value: str, least: int, most: int, usage: str, path: str,
                   lineno: int) -> list[str]:
    """The words of an ``@key`` line's value, ``least`` to ``most`` of them, else its usage."""
    words = value.split()
    if not least <= len(words) <= most:
        raise LayoutError(path, lineno, f"@{key} = {_shown(value)}: {usage}")
    return words


def _parse_light(value: str, path: str, lineno: int) -> tuple[float, float, float, float, float | None]:
    """``X Y Z INTENSITY_CD [CONE_DEG]`` of an ``@light`` line."""
    usage = "expected '@light = X Y Z INTENSITY_CD [CONE_DEG]' (m, m, m, candela, degrees)"
    words = _setting_words("light", value, 4, 5, usage, path, lineno)
    numbers = _ranged_numbers("light", words, (("X", "coordinate_m"), ("Y", "coordinate_m"), ("Z", "coordinate_m"),
                                               ("INTENSITY_CD", "intensity_cd"), ("CONE_DEG", "cone_deg")),
                              usage, path, lineno)
    x, y, z, cd = numbers[:4]
    lo, hi = LIGHT_LIMITS["height_m"]  # as typed, before @scale (as every length)
    if not lo <= z <= hi:
        raise LayoutError(path, lineno, f"@light: Z = {_bare(words[2])} m: expected {lo:g} <= Z <= {hi:g} "
                                        f"(m above the track)")
    return x, y, z, cd, (numbers[4] if len(numbers) == 5 else None)


def _parse_shade(value: str, path: str, lineno: int) -> tuple[float, ...]:
    """``X Y LENGTH WIDTH HEADING_DEG TRANSMISSION`` of an ``@shade`` line."""
    usage = "expected '@shade = X Y LENGTH WIDTH HEADING_DEG TRANSMISSION' (m, m, m, m, degrees, 0..1)"
    words = _setting_words("shade", value, 6, 6, usage, path, lineno)
    return tuple(_ranged_numbers("shade", words, (("X", "coordinate_m"), ("Y", "coordinate_m"),
                                                  ("LENGTH", "size_m"), ("WIDTH", "size_m"),
                                                  ("HEADING_DEG", "heading_deg"), ("TRANSMISSION", "transmission")),
                                 usage, path, lineno))


def _parse_barcode(value: str, path: str, lineno: int) -> tuple[float, ...]:
    """``X Y CODE HEADING_DEG [MODULE [LENGTH]]`` of an ``@barcode`` line."""
    usage = "expected '@barcode = X Y CODE HEADING_DEG [MODULE [LENGTH]]' (m, m, 0..15, degrees, m, m)"
    words = _setting_words("barcode", value, 4, 6, usage, path, lineno)
    numbers = _ranged_numbers("barcode", words, (("X", "coordinate_m"), ("Y", "coordinate_m"), ("CODE", "code"),
                                                 ("HEADING_DEG", "heading_deg"), ("MODULE", "module_m"),
                                                 ("LENGTH", "length_m")), usage, path, lineno, MARK_LIMITS)
    if numbers[2] != int(numbers[2]):
        raise LayoutError(path, lineno, f"@barcode: CODE = {_bare(words[2])}: expected a whole number 0 .. 15")
    numbers += [DEFAULT_MODULE_M, DEFAULT_LENGTH_M][len(numbers) - 4:]
    return tuple(numbers)


def _parse_box(value: str, path: str, lineno: int) -> tuple[float, ...]:
    """``X Y LENGTH WIDTH HEIGHT [HEADING_DEG [REFLECTANCE]]`` of an ``@box`` line."""
    usage = "expected '@box = X Y LENGTH WIDTH HEIGHT [HEADING_DEG [REFLECTANCE]]' (m, m, m, m, m, degrees, 0..1)"
    words = _setting_words("box", value, 5, 7, usage, path, lineno)
    numbers = _ranged_numbers("box", words, (("X", "coordinate_m"), ("Y", "coordinate_m"), ("LENGTH", "size_m"),
                                             ("WIDTH", "size_m"), ("HEIGHT", "size_m"), ("HEADING_DEG", "heading_deg"),
                                             ("REFLECTANCE", "reflectance")), usage, path, lineno, SOLID_LIMITS)
    numbers += [0.0, WHITE_REFLECTANCE][len(numbers) - 5:]
    return tuple(numbers)


def _number(text: str) -> float | None:
    """A decimal number of at most MAX_NUMBER_CHARS characters, else ``None``."""
    if len(text) > MAX_NUMBER_CHARS or not _NUMBER.match(text):
        return None
    return float(text)


def _parse_piece(body: str, path: str, lineno: int) -> tuple[LayoutEntry, int]:
    body = re.sub(r"\s*=\s*", "=", body)
    word, *tokens = body.split()
    kind_name = word.upper()
    if kind_name not in PIECE_NAMES or not word.isascii():  # 'ſtraight'.upper() == 'STRAIGHT'
        raise LayoutError(path, lineno, f"unknown piece {_shown(word)} (expected one of "
                                        f"{', '.join(PIECE_NAMES)}{_did_you_mean(kind_name, PIECE_NAMES)})")
    kind = PieceType[kind_name]
    specs = PARAMS[kind]
    params: dict[str, float] = {}
    repeat: int | None = None
    for token in tokens:
        rep = _REPEAT.match(token)
        if rep and "=" not in token:
            if repeat is not None:
                raise LayoutError(path, lineno, f"{kind_name}: repeat count given twice")
            count = rep.group(1)
            if (not count.isascii() or not count.isdigit() or len(count) > 6
                    or not 1 <= int(count) <= MAX_REPEAT):
                raise LayoutError(path, lineno, f"{kind_name} {_bare(token)}: expected a repeat "
                                                f"count x1 to x{MAX_REPEAT}")
            repeat = int(count)
            continue
        key, sep, value = token.partition("=")
        if not sep:
            raise LayoutError(path, lineno, f"{kind_name}: unexpected {_shown(token)} (expected "
                                            "key=value parameters or a repeat count like x3)")
        key_l = key.lower()
        if key_l not in specs or not key.isascii():
            known = ", ".join(specs)
            raise LayoutError(path, lineno, f"{kind_name}: unknown parameter {_shown(key)} (expected "
                                            f"{known}{_did_you_mean(key_l, specs)})")
        if key_l in params:
            raise LayoutError(path, lineno, f"{kind_name}: parameter {key_l} given twice")
        spec = specs[key_l]
        number = _number(value)
        if number is None:
            raise LayoutError(path, lineno, f"{kind_name} {key_l}={_bare(value)}: expected a "
                                            f"number ({spec.unit})")
        if not spec.contains(number):
            raise LayoutError(path, lineno, f"{kind_name} {key_l}={_bare(value)}: expected "
                                            f"{range_text(spec)}")
        params[key_l] = number
    return LayoutEntry(kind, params, lineno), (repeat or 1)
