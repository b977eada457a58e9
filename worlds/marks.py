"""Printed marks that only the cameras read: Pixy2 barcodes on the floor (docs/pixy2.md, "Barcodes").

A :class:`Barcode` is a white card with black bars lying flat at world ``(x_m, y_m)``. Its bars
run along ``heading_rad`` (the direction a car drives over it), so the code is read across
them, left to right as that car sees it: along the rows of a camera's image, where the Pixy2
looks for barcodes. Layouts place one with ``@barcode = X Y CODE HEADING_DEG [MODULE [LENGTH]]``
(trackgen.layout); ``trackgen build`` writes them into ``track.json`` and into ``world.sdf`` (an
``nxpcup:barcode`` element each, read back by ``worlds.sdf_read``, and flat box visuals so
Gazebo shows them). The simulator paints them into the track's raster above the track, so
every camera sees them; they are not road (the judge ignores them).

The pattern is our own drawing of the 4-bit code the Pixy2 firmware decodes (charmedlabs/pixy2,
``src/device/main_m4/src/line.cpp``: ``detectCode``, ``decodeCode``; the official printed
barcodes may be drawn differently but decode the same). Read left to right: a narrow black
start bar, then the 4 bits, most significant first. A bit is the colour of the element that
completes it (black 1, white 0): one wide element when the next element has that colour,
else two narrow ones (the second of that colour). A narrow black stop bar follows when the last
element is white, and narrow white-black pairs until the code has ``MIN_ELEMENTS`` elements
(the firmware reads 7 to 9 bars and gaps between a quiet zone at least 4 start-bar widths
wide on each side). Narrow = ``module_m``, wide = ``WIDE_MODULES`` modules; the card adds
``QUIET_MODULES`` of white on each side across and ``MARGIN_MODULES`` before and after.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import shapely

from worlds.lighting import float_of, nxpcup_child, nxpcup_tag

CODE_BITS = 4
MIN_ELEMENTS = 7        # the firmware's fewest bars and gaps of a code (LINE_MMC_MIN_EDGES - 1)
WIDE_MODULES = 2.5      # a wide element in narrow ones (our drawing; the decoder splits at the widest gap)
QUIET_MODULES = 5.0     # white across before and after the bars (the firmware needs >= 4 start bars)
MARGIN_MODULES = 2.0    # white along, before and after the bars
LIMITS = {"code": (0, 15), "module_m": (0.002, 0.1), "length_m": (0.01, 1.0),
          "coordinate_m": (-10_000.0, 10_000.0), "heading_deg": (-360.0, 360.0)}
DEFAULT_MODULE_M = 0.01  # 1 cm: ~5 Pixy2 pixels at 0.35 m (examples/pixy2_car.toml), 2 raster pixels
DEFAULT_LENGTH_M = 0.05  # bars 5 cm long: a dozen image rows at that distance (the firmware votes over rows)
FIELDS = ("x_m", "y_m", "code", "heading_rad", "module_m", "length_m")


def pattern(code: int) -> list[tuple[bool, float]]:
    """The elements of ``code`` left to right: ``(black, width in modules)`` (module docstring)."""
    if not 0 <= code < 1 << CODE_BITS:
        raise ValueError(f"barcode {code}: expected 0 .. {(1 << CODE_BITS) - 1}")
    out = [(True, 1.0)]
    for i in range(CODE_BITS - 1, -1, -1):
        black = bool(code >> i & 1)
        if out[-1][0] != black:            # the next element has the bit's colour: one wide element
            out.append((black, WIDE_MODULES))
        else:                              # two narrow: the other colour, then the bit's
            out += [(not black, 1.0), (black, 1.0)]
    if not out[-1][0]:
        out.append((True, 1.0))
    while len(out) < MIN_ELEMENTS:
        out += [(False, 1.0), (True, 1.0)]
    return out


@dataclass(frozen=True)
class Barcode:
    """A Pixy2 barcode ``code`` (0-15) centred at world ``(x_m, y_m)``, bars along
    ``heading_rad``, narrow element ``module_m`` wide, bars ``length_m`` long."""

    x_m: float
    y_m: float
    code: int
    heading_rad: float = 0.0
    module_m: float = DEFAULT_MODULE_M
    length_m: float = DEFAULT_LENGTH_M

    @property
    def bars_width_m(self) -> float:
        """Across, from the start bar's outer edge to the last bar's."""
        return self.module_m * sum(w for _, w in pattern(self.code))

    @property
    def card_size_m(self) -> tuple[float, float]:
        """``(along, across)`` the heading: the white card under the bars."""
        return (self.length_m + 2.0 * MARGIN_MODULES * self.module_m,
                self.bars_width_m + 2.0 * QUIET_MODULES * self.module_m)

    def _place(self, along0: float, along1: float, left0: float, left1: float) -> shapely.Polygon:
        """A rectangle in the card's frame (``along`` the heading, ``left`` of it) placed in the world."""
        c, s = math.cos(self.heading_rad), math.sin(self.heading_rad)
        pts = [(self.x_m + a * c - l * s, self.y_m + a * s + l * c)
               for a, l in ((along0, left0), (along1, left0), (along1, left1), (along0, left1))]
        return shapely.Polygon(pts)

    def card(self) -> shapely.Polygon:
        """The white card (world metres)."""
        along, across = self.card_size_m
        return self._place(-along / 2, along / 2, -across / 2, across / 2)

    def bars(self) -> list[shapely.Polygon]:
        """The black bars (world metres), left to right as a car driving along the heading sees them."""
        out, left = [], self.bars_width_m / 2.0  # the car's left is +left; reading starts there
        for black, w in pattern(self.code):
            right = left - w * self.module_m
            if black:
                out.append(self._place(-self.length_m / 2, self.length_m / 2, right, left))
            left = right
        return out

    def to_json(self) -> dict:
        return {k: getattr(self, k) for k in FIELDS}


def _checked(values, where: str) -> Barcode:
    x, y, code, heading, module, length = values
    for name, v in zip(FIELDS, values):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"{where}: {name} = {v!r}: expected a finite number")
    if code != int(code) or not LIMITS["code"][0] <= code <= LIMITS["code"][1]:
        raise ValueError(f"{where}: code = {code!r}: expected a whole number 0 .. 15")
    for name, v in (("module_m", module), ("length_m", length)):
        lo, hi = LIMITS[name]
        if not lo <= v <= hi:
            raise ValueError(f"{where}: {name} = {v!r}: expected {lo:g} .. {hi:g}")
    return Barcode(float(x), float(y), int(code), float(heading), float(module), float(length))


# -- SDF ---------------------------------------------------------------------------------------
def write_sdf(world: ET.Element, barcodes: tuple[Barcode, ...], fmt, surface_z_m: float) -> None:
    """Append ``barcodes`` to an SDF ``<world>``: one ``<nxpcup:barcode>`` element each (what the
    simulator reads) and a static model ``barcodes`` of thin box visuals (what Gazebo shows;
    no collisions: a printed card) on the track's top ``surface_z_m``. ``fmt``: the writer's
    number formatter."""
    if not barcodes:
        return
    for b in barcodes:
        el = ET.SubElement(world, nxpcup_tag("barcode"))
        for key in FIELDS:
            ET.SubElement(el, nxpcup_tag(key)).text = str(b.code) if key == "code" else fmt(getattr(b, key))
    model = ET.SubElement(world, "model", name="barcodes")
    ET.SubElement(model, "static").text = "true"
    link = ET.SubElement(model, "link", name="cards")
    for i, b in enumerate(barcodes):
        for j, (poly, rgba, z) in enumerate([(b.card(), "1 1 1 1", 0.0005)]
                                            + [(bar, "0 0 0 1", 0.0010) for bar in b.bars()]):
            _box_visual(link, f"barcode_{i}_{j}", poly, b.heading_rad, surface_z_m, z, rgba, fmt)


def _box_visual(link: ET.Element, name: str, poly: shapely.Polygon, yaw: float, surface_z_m: float,
                z_m: float, rgba: str, fmt) -> None:
    """A flat box over the rectangle ``poly`` (its sides along ``yaw``) from ``surface_z_m`` up
    ``z_m`` (a Gazebo visual only)."""
    (x0, y0), (x1, y1), (x2, y2) = list(poly.exterior.coords)[:3]
    c = poly.centroid
    visual = ET.SubElement(link, "visual", name=name)
    ET.SubElement(visual, "pose").text = fmt(c.x, c.y, surface_z_m + z_m / 2.0, 0, 0, yaw)
    box = ET.SubElement(ET.SubElement(visual, "geometry"), "box")
    ET.SubElement(box, "size").text = fmt(math.hypot(x1 - x0, y1 - y0), math.hypot(x2 - x1, y2 - y1), z_m)
    mat = ET.SubElement(visual, "material")
    for tag in ("ambient", "diffuse"):
        ET.SubElement(mat, tag).text = rgba


def from_sdf_world(world: ET.Element) -> tuple[Barcode, ...]:
    """The ``<nxpcup:barcode>`` elements of an SDF ``<world>`` (those with every number valid)."""
    out = []
    for el in world.findall(nxpcup_tag("barcode")) + world.findall("nxpcup:barcode"):
        values = [float_of(nxpcup_child(el, key)) for key in FIELDS]
        if None in values:
            continue
        try:
            out.append(_checked(values, "barcode"))
        except ValueError:
            continue
    return tuple(out)
