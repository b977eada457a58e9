"""The light on a track and its surfaces' reflectances (docs/camera.md, "Light in the world").

A :class:`TrackLighting` is an ambient illuminance (lux) on the whole track plus point or spot
lights (position in world metres, luminous intensity in candela, spots pointing straight down
with a full cone angle), shades (a tunnel's roof or a shadow over a rectangle of the floor,
letting through a fraction of all the light), and the reflectances of the lane, the black lines and the floor (the
fraction of light a matte surface returns) with a small specular (glossy) term. Layouts set it
with ``@ambient_lux``, ``@light``, ``@shade``, ``@lane_reflectance``, ``@line_reflectance``,
``@floor_reflectance``, ``@specular`` (trackgen.layout); ``trackgen build`` writes it into
``world.sdf`` as SDF ``<light>`` elements (for Gazebo) with the photometric numbers in elements
of the ``nxpcup`` XML namespace, and into ``track.json``; ``worlds.sdf_read`` reads it back,
and reads the lights of any other world by the Gazebo convention of :func:`from_sdf_world`.

Illuminance on the (horizontal) track surface at a point ``q``, from a light of intensity ``I``
at height ``h`` above the surface and distance ``d``: ``E = I cos(theta) / d^2 = I h / d^3``
(inverse-square law with Lambert's cosine; a spot gives this inside its cone, fading to 0
over the last 10 % of its half-angle). Under a shade the sum is multiplied by its
``transmission``, rising linearly to 1 over the last ``SHADE_EDGE_M`` inside its rectangle
(the soft edge of a shadow, the light coming in at a tunnel's mouth).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

NS = "https://github.com/nxpcup-sim/ns/lighting"  # the XML namespace of our photometric elements
ET.register_namespace("nxpcup", NS)

# EN 12193 (sports lighting): 500 lux for a class II indoor hall (regional competition);
# school gyms (class III) 200-300 lux, class I halls 750 lux.
DEFAULT_AMBIENT_LUX = 500.0
# The simulator's grey levels (simrunner.track.raster); the surfaces' default reflectances are
# those grey levels / 255: matte white print 0.922 (white paper and matte white PVC: 0.8-0.95),
# black print 0.059 (0.03-0.1), a grey hall floor 0.157.
LANE_GRAY, LINE_GRAY, FLOOR_GRAY = 235, 15, 40
LANE_REFLECTANCE, LINE_REFLECTANCE, FLOOR_REFLECTANCE = LANE_GRAY / 255, LINE_GRAY / 255, FLOOR_GRAY / 255
DEFAULT_SPECULAR = 0.03  # fraction of light reflected glossily by matte print (Blinn-Phong k_s)
SHININESS = 30.0  # Blinn-Phong exponent: a broad highlight, as on a satin-printed surface
GAZEBO_LUX = 500.0  # Gazebo lights have no units: a white (diffuse 1) light straight down = this
SPOT_EDGE = 0.9  # a spot is full strength out to 90 % of its half-angle, then fades to 0
SHADE_EDGE_M = 0.05  # a shade's edge: full transmission outside, its own 5 cm inside (estimate)

LIMITS = {  # the range of each number (layout errors and readers say these)
    "ambient_lux": (0.0, 200_000.0),
    "intensity_cd": (0.0, 1e7),
    "height_m": (0.05, 100.0),
    "cone_deg": (1.0, 179.0),
    "reflectance": (0.0, 1.0),
    "specular": (0.0, 1.0),
    "coordinate_m": (-10_000.0, 10_000.0),
    "size_m": (0.01, 1_000.0),
    "heading_deg": (-360.0, 360.0),
    "transmission": (0.0, 1.0),
}


@dataclass(frozen=True)
class Light:
    """A point light (``cone_deg`` None) or a spot pointing straight down with that full cone
    angle, at world ``(x_m, y_m, z_m)``, of luminous intensity ``intensity_cd``."""

    x_m: float
    y_m: float
    z_m: float
    intensity_cd: float
    cone_deg: float | None = None

    def illuminance_lux(self, x_m, y_m, surface_z_m: float):
        """Illuminance (lux) on the horizontal surface at ``z = surface_z_m``, points
        ``(x_m, y_m)`` (arrays of one shape)."""
        h = self.z_m - surface_z_m
        if h <= 0.0:
            return np.zeros(np.shape(x_m))
        dx = np.asarray(x_m) - self.x_m
        dy = np.asarray(y_m) - self.y_m
        d2 = dx * dx + dy * dy + h * h
        e = self.intensity_cd * h / (d2 * np.sqrt(d2))
        if self.cone_deg is not None:
            cos_outer = math.cos(math.radians(self.cone_deg) / 2.0)
            cos_inner = math.cos(SPOT_EDGE * math.radians(self.cone_deg) / 2.0)
            cos_angle = h / np.sqrt(d2)
            e = e * np.clip((cos_angle - cos_outer) / (cos_inner - cos_outer), 0.0, 1.0)
        return e


@dataclass(frozen=True)
class Shade:
    """A tunnel's roof or a shadow: the ``length_m x width_m`` rectangle centred at world
    ``(x_m, y_m)``, its length along ``heading_rad``, where ``transmission`` of the light
    reaches the floor (module docstring)."""

    x_m: float
    y_m: float
    length_m: float
    width_m: float
    heading_rad: float
    transmission: float

    def factor(self, x_m, y_m) -> np.ndarray:
        """Light factor at the points: 1 outside, ``transmission`` deep inside."""
        c, s = math.cos(self.heading_rad), math.sin(self.heading_rad)
        dx, dy = np.asarray(x_m) - self.x_m, np.asarray(y_m) - self.y_m
        along, across = dx * c + dy * s, -dx * s + dy * c
        depth = np.minimum(self.length_m / 2.0 - np.abs(along), self.width_m / 2.0 - np.abs(across))
        inside = np.clip(depth / SHADE_EDGE_M, 0.0, 1.0)
        return 1.0 - (1.0 - self.transmission) * inside


@dataclass(frozen=True)
class TrackLighting:
    """The light on a track and its surfaces (module docstring). The default is a hall of
    ``DEFAULT_AMBIENT_LUX`` with no lamps and the simulator's grey levels as reflectances."""

    ambient_lux: float = DEFAULT_AMBIENT_LUX
    lights: tuple[Light, ...] = ()
    shades: tuple[Shade, ...] = ()
    lane_reflectance: float = LANE_REFLECTANCE
    line_reflectance: float = LINE_REFLECTANCE
    floor_reflectance: float = FLOOR_REFLECTANCE
    specular: float = DEFAULT_SPECULAR

    def is_default(self) -> bool:
        return self == TrackLighting()

    def illuminance_lux(self, x_m, y_m, surface_z_m: float = 0.0):
        """Ambient plus every light (lux) at the surface points ``(x_m, y_m)``, times the
        shades: a scalar when there are no lights and no shades, else an array of their shape."""
        if not self.lights and not self.shades:
            return self.ambient_lux
        e = np.full(np.shape(x_m), self.ambient_lux)
        for light in self.lights:
            e = e + light.illuminance_lux(x_m, y_m, surface_z_m)
        return e * self.shade_factor(x_m, y_m) if self.shades else e

    def shade_factor(self, x_m, y_m):
        """The product of the shades' light factors at the points (1 without shades)."""
        f = 1.0
        for shade in self.shades:
            f = f * shade.factor(x_m, y_m)
        return f

    def illuminance_grid(self, xs_m: np.ndarray, ys_m: np.ndarray, surface_z_m: float = 0.0) -> np.ndarray:
        """Illuminance (lux) on the grid of columns ``xs_m`` and rows ``ys_m``:
        ``(len(ys_m), len(xs_m))`` (a top view: preview.png, the debug video's map)."""
        x, y = np.meshgrid(np.asarray(xs_m, np.float64), np.asarray(ys_m, np.float64))
        return np.broadcast_to(self.illuminance_lux(x, y, surface_z_m), x.shape)

    def reflectance_of_gray(self) -> np.ndarray:
        """``(256,)`` reflectance of each raster grey level: the lane's, lines' and floor's
        grey get this track's reflectances, any other grey (imported worlds) gray / 255."""
        lut = np.arange(256, dtype=np.float64) / 255.0
        lut[LANE_GRAY] = self.lane_reflectance
        lut[LINE_GRAY] = self.line_reflectance
        lut[FLOOR_GRAY] = self.floor_reflectance
        return lut

    # -- track.json ----------------------------------------------------------------------
    def to_json(self) -> dict:
        return {"ambient_lux": self.ambient_lux,
                "lights": [{"x_m": l.x_m, "y_m": l.y_m, "z_m": l.z_m, "intensity_cd": l.intensity_cd,
                            "cone_deg": l.cone_deg} for l in self.lights],
                **({"shades": [{k: getattr(sh, k) for k in SHADE_FIELDS} for sh in self.shades]}
                   if self.shades else {}),
                "lane_reflectance": self.lane_reflectance, "line_reflectance": self.line_reflectance,
                "floor_reflectance": self.floor_reflectance, "specular": self.specular}


SHADE_FIELDS = ("x_m", "y_m", "length_m", "width_m", "heading_rad", "transmission")
_SHADE_LIMITS = ("coordinate_m", "coordinate_m", "size_m", "size_m", None, "transmission")


def _number(value, name: str, where: str, key: str | None) -> float:
    if key is None:  # any finite number
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"{where}: {name} = {value!r}: expected a finite number")
        return float(value)
    lo, hi = LIMITS[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not lo <= value <= hi:
        raise ValueError(f"{where}: {name} = {value!r}: expected a number in [{lo:g}, {hi:g}]")
    return float(value)


def from_json(doc, where: str) -> TrackLighting:
    """A :class:`TrackLighting` from its ``to_json`` form; ``ValueError`` naming ``where``
    and the field for anything else."""
    if not isinstance(doc, dict):
        raise ValueError(f"{where}: lighting: expected an object")
    lights = []
    for i, item in enumerate(doc.get("lights", [])):
        if not isinstance(item, dict):
            raise ValueError(f"{where}: lighting.lights[{i}]: expected an object")
        cone = item.get("cone_deg")
        lights.append(Light(*(_number(item.get(k), f"lighting.lights[{i}].{k}", where, lim) for k, lim in
                              (("x_m", "coordinate_m"), ("y_m", "coordinate_m"), ("z_m", "coordinate_m"),
                               ("intensity_cd", "intensity_cd"))),
                            None if cone is None else _number(cone, f"lighting.lights[{i}].cone_deg", where,
                                                              "cone_deg")))
    shades = []
    for i, item in enumerate(doc.get("shades", [])):
        if not isinstance(item, dict):
            raise ValueError(f"{where}: lighting.shades[{i}]: expected an object")
        shades.append(Shade(*(_number(item.get(k), f"lighting.shades[{i}].{k}", where, lim)
                              for k, lim in zip(SHADE_FIELDS, _SHADE_LIMITS))))
    d = TrackLighting()
    return TrackLighting(
        ambient_lux=_number(doc.get("ambient_lux", d.ambient_lux), "lighting.ambient_lux", where, "ambient_lux"),
        lights=tuple(lights), shades=tuple(shades),
        lane_reflectance=_number(doc.get("lane_reflectance", d.lane_reflectance), "lighting.lane_reflectance",
                                 where, "reflectance"),
        line_reflectance=_number(doc.get("line_reflectance", d.line_reflectance), "lighting.line_reflectance",
                                 where, "reflectance"),
        floor_reflectance=_number(doc.get("floor_reflectance", d.floor_reflectance), "lighting.floor_reflectance",
                                  where, "reflectance"),
        specular=_number(doc.get("specular", d.specular), "lighting.specular", where, "specular"))


# -- SDF -------------------------------------------------------------------------------------
def nxpcup_tag(tag: str) -> str:
    """``tag`` in our XML namespace (``{NS}tag``), for ElementTree (shared with worlds.marks)."""
    return f"{{{NS}}}{tag}"


def nxpcup_child(el: ET.Element | None, tag: str) -> ET.Element | None:
    """The child ``nxpcup:tag`` of ``el``: namespace-resolved (``{NS}tag``) or, from a parser
    that keeps prefixes (worlds.sdf_xml), ``nxpcup:tag``."""
    if el is None:
        return None
    found = el.find(nxpcup_tag(tag))
    return found if found is not None else el.find(f"nxpcup:{tag}")


def write_sdf(world: ET.Element, lighting: TrackLighting, fmt) -> None:
    """Append ``lighting`` to an SDF ``<world>``: one ``<light>`` per lamp (point or spot,
    pointing down, inverse-square attenuation, white) carrying ``<nxpcup:intensity_cd>``, and
    one ``<nxpcup:lighting>`` element with the ambient level and the reflectances. ``fmt``:
    the writer's number formatter."""
    for i, light in enumerate(lighting.lights, start=1):
        el = ET.SubElement(world, "light", name=f"lamp_{i}", type="point" if light.cone_deg is None else "spot")
        ET.SubElement(el, "cast_shadows").text = "false"
        ET.SubElement(el, "pose").text = fmt(light.x_m, light.y_m, light.z_m, 0, 0, 0)
        ET.SubElement(el, "diffuse").text = "1 1 1 1"
        ET.SubElement(el, "specular").text = "0.1 0.1 0.1 1"
        att = ET.SubElement(el, "attenuation")
        ET.SubElement(att, "range").text = fmt(100.0)
        ET.SubElement(att, "constant").text = fmt(0.0)
        ET.SubElement(att, "linear").text = fmt(0.0)
        ET.SubElement(att, "quadratic").text = fmt(1.0)
        ET.SubElement(el, "direction").text = "0 0 -1"
        if light.cone_deg is not None:
            half = math.radians(light.cone_deg) / 2.0
            spot = ET.SubElement(el, "spot")
            ET.SubElement(spot, "inner_angle").text = fmt(SPOT_EDGE * half)
            ET.SubElement(spot, "outer_angle").text = fmt(half)
            ET.SubElement(spot, "falloff").text = fmt(1.0)
        ET.SubElement(el, nxpcup_tag("intensity_cd")).text = fmt(light.intensity_cd)
    info = ET.SubElement(world, nxpcup_tag("lighting"))
    for key in ("ambient_lux", "lane_reflectance", "line_reflectance", "floor_reflectance", "specular"):
        ET.SubElement(info, nxpcup_tag(key)).text = fmt(getattr(lighting, key))
    for shade in lighting.shades:
        el = ET.SubElement(info, nxpcup_tag("shade"))
        for key in SHADE_FIELDS:
            ET.SubElement(el, nxpcup_tag(key)).text = fmt(getattr(shade, key))


def _gray(text: str | None) -> float:
    try:
        rgb = [float(v) for v in (text or "1 1 1").split()[:3]]
        return max(0.0, sum(rgb) / len(rgb)) if rgb and all(math.isfinite(v) for v in rgb) else 1.0
    except ValueError:
        return 1.0


def float_of(el: ET.Element | None, default: float | None = None) -> float | None:
    """The first number of ``el``'s text, or ``default`` (no element, no text, not a finite number)."""
    if el is None or el.text is None:
        return default
    try:
        v = float(el.text.split()[0])
    except (ValueError, IndexError):
        return default
    return v if math.isfinite(v) else default


def from_sdf_world(world: ET.Element, pose_of) -> TrackLighting | None:
    """The lighting of an SDF ``<world>`` (None when it has no ``<light>`` and no
    ``<nxpcup:lighting>``: the caller's default then).

    Our own worlds carry photometric numbers (``nxpcup`` elements). Any other world's lights
    have no units; they are read by this convention: the ambient level is the default hall's
    (``DEFAULT_AMBIENT_LUX``: a directional light, a Gazebo world's sun, is not read, the
    hall's ambient stands for it), and a point or spot light without ``<nxpcup:intensity_cd>``
    has ``GAZEBO_LUX x (mean of its diffuse RGB)`` candela (500 lux one metre below a white
    one). ``pose_of(el)``: the world position (x, y, z) of a light element."""
    info = nxpcup_child(world, "lighting")
    lamps = [el for el in world.findall("light") if el.get("type", "point") in ("point", "spot")]
    if info is None and not lamps:
        return None
    d = TrackLighting()
    ambient = float_of(nxpcup_child(info, "ambient_lux"), d.ambient_lux) if info is not None else d.ambient_lux
    lights = []
    for el in lamps:
        gray = _gray((el.find("diffuse").text if el.find("diffuse") is not None else None))
        x, y, z = (float(v) for v in pose_of(el))
        cd = float_of(nxpcup_child(el, "intensity_cd"), GAZEBO_LUX * gray)
        cone = None
        if el.get("type") == "spot":
            outer = float_of(el.find("spot/outer_angle") if el.find("spot") is not None else None)
            cone = min(max(math.degrees(2.0 * outer), LIMITS["cone_deg"][0]), LIMITS["cone_deg"][1]) \
                if outer is not None else 90.0
        lights.append(Light(x, y, z, max(cd, 0.0), cone))

    def value(key: str, default: float) -> float:  # a fraction: clamped to [0, 1]
        v = default if info is None else float_of(nxpcup_child(info, key), default)
        return min(max(v, 0.0), 1.0)

    shades = []
    if info is not None:
        for el in info.findall(nxpcup_tag("shade")) + info.findall("nxpcup:shade"):
            numbers = [float_of(nxpcup_child(el, key)) for key in SHADE_FIELDS]
            if None not in numbers:  # a shade without all its numbers is not ours to guess
                x, y, length, width, heading, transmission = numbers
                shades.append(Shade(x, y, max(length, 0.0), max(width, 0.0), heading,
                                    min(max(transmission, 0.0), 1.0)))
    return TrackLighting(
        ambient_lux=min(max(ambient, 0.0), LIMITS["ambient_lux"][1]), lights=tuple(lights),
        shades=tuple(shades),
        lane_reflectance=value("lane_reflectance", d.lane_reflectance),
        line_reflectance=value("line_reflectance", d.line_reflectance),
        floor_reflectance=value("floor_reflectance", d.floor_reflectance),
        specular=value("specular", d.specular))
