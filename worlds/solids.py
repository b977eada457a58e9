"""Objects standing on the track: :class:`Solid`, a box (the rules' obstacle cube, the
emergency-braking block), in the world frame.

A solid stands on the track's surface: its footprint is a ``length_m x width_m`` rectangle
centred at ``(x_m, y_m)``, ``length_m`` along ``yaw_rad`` (radians, counter-clockwise from
+x), ``height_m`` tall. ``reflectance`` is the fraction of light its faces return (the
cameras' shade, :mod:`simrunner.sensors.solids`), ``mass_kg`` its mass. The simulator makes
it a box in the dartpy world, the
cameras see it, range sensors measure it; :meth:`Solid.sdf` writes it as a Gazebo model. The
simulator holds it fixed (a touch ends an attempt); ``mass_kg`` is for the SDF model.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from worlds.marks import float_of, nxpcup_child, nxpcup_tag

# expanded polystyrene: 15-30 kg/m^3 for the usual grades (ours: 20); the rules: "Styrofoam or
# similar" (rules summary sections 4.2, 4.4)
EPS_DENSITY_KGPM3 = 20.0
LIMITS = {"coordinate_m": (-10_000.0, 10_000.0), "size_m": (0.005, 10.0), "heading_deg": (-360.0, 360.0),
          "reflectance": (0.0, 1.0)}
FIELDS = ("x_m", "y_m", "length_m", "width_m", "height_m", "yaw_rad", "reflectance", "mass_kg")
WHITE_REFLECTANCE = 0.85   # white polystyrene (ours; the kit's lane is 0.92)
BLACK_REFLECTANCE = 0.05   # matte black (the kit's lines: 0.06)


@dataclass(frozen=True)
class Solid:
    """A box standing on the track (module docstring); lengths in metres."""

    name: str
    x_m: float
    y_m: float
    length_m: float
    width_m: float
    height_m: float
    yaw_rad: float = 0.0
    reflectance: float = WHITE_REFLECTANCE
    mass_kg: float = 0.16

    def __post_init__(self) -> None:
        for f in ("x_m", "y_m", "length_m", "width_m", "height_m", "yaw_rad", "reflectance", "mass_kg"):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"Solid {self.name!r}: {f} = {v!r}: expected a finite number")
        if min(self.length_m, self.width_m, self.height_m, self.mass_kg) <= 0:
            raise ValueError(f"Solid {self.name!r}: sizes and mass must be > 0")
        if not 0.0 <= self.reflectance <= 1.0:
            raise ValueError(f"Solid {self.name!r}: reflectance = {self.reflectance!r}: expected 0 .. 1")

    def corners_xy(self) -> np.ndarray:
        """``(4, 2)`` world corners of the footprint, counter-clockwise."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        hl, hw = self.length_m / 2.0, self.width_m / 2.0
        local = np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]])
        return np.column_stack((self.x_m + c * local[:, 0] - s * local[:, 1],
                                self.y_m + s * local[:, 0] + c * local[:, 1]))

    def gap_m(self, x_m: float, y_m: float, yaw_rad: float, half_length_m: float, half_width_m: float) -> float:
        """The widest gap between the footprint and that rectangle along the separating axes
        (the two rectangles' edge directions): <= 0 when they overlap, else a lower bound of
        their distance (m). The car's tyres touch the solid where it is <= 0."""
        dx, dy = x_m - self.x_m, y_m - self.y_m
        c1, s1, c2, s2 = math.cos(self.yaw_rad), math.sin(self.yaw_rad), math.cos(yaw_rad), math.sin(yaw_rad)
        a1, b1, a2, b2 = 0.5 * self.length_m, 0.5 * self.width_m, half_length_m, half_width_m
        gap = -math.inf
        for ux, uy in ((c1, s1), (-s1, c1), (c2, s2), (-s2, c2)):
            reach = (a1 * abs(ux * c1 + uy * s1) + b1 * abs(-ux * s1 + uy * c1)
                     + a2 * abs(ux * c2 + uy * s2) + b2 * abs(-ux * s2 + uy * c2))
            gap = max(gap, abs(dx * ux + dy * uy) - reach)
        return gap

    def to_json(self) -> dict:
        return {"name": self.name, "x_m": self.x_m, "y_m": self.y_m, "length_m": self.length_m,
                "width_m": self.width_m, "height_m": self.height_m, "yaw_rad": self.yaw_rad,
                "reflectance": self.reflectance, "mass_kg": self.mass_kg}

    def sdf(self, surface_z_m: float = 0.0) -> str:
        """A Gazebo ``<model>`` of this box (a movable link with its mass and box inertia)."""
        size = f"{self.length_m:.6g} {self.width_m:.6g} {self.height_m:.6g}"
        g = f"{self.reflectance:.3f}"
        m = self.mass_kg
        ixx = m * (self.width_m ** 2 + self.height_m ** 2) / 12.0
        iyy = m * (self.length_m ** 2 + self.height_m ** 2) / 12.0
        izz = m * (self.length_m ** 2 + self.width_m ** 2) / 12.0
        return (f'<model name="{self.name}"><pose>{self.x_m:.6g} {self.y_m:.6g} '
                f'{surface_z_m + self.height_m / 2.0:.6g} 0 0 {self.yaw_rad:.6g}</pose><link name="body">'
                f"<inertial><mass>{m:.6g}</mass><inertia><ixx>{ixx:.6g}</ixx><iyy>{iyy:.6g}</iyy>"
                f"<izz>{izz:.6g}</izz><ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia></inertial>"
                f"<collision name=\"collision\"><geometry><box><size>{size}</size></box></geometry></collision>"
                f"<visual name=\"visual\"><geometry><box><size>{size}</size></box></geometry><material>"
                f"<ambient>{g} {g} {g} 1</ambient><diffuse>{g} {g} {g} 1</diffuse></material></visual>"
                "</link></model>")


def box_mass_kg(length_m: float, width_m: float, height_m: float) -> float:
    """The mass of a polystyrene box of that size (EPS_DENSITY_KGPM3)."""
    return EPS_DENSITY_KGPM3 * length_m * width_m * height_m


def write_sdf(world: ET.Element, solids: tuple, surface_z_m: float) -> None:
    """Append ``solids`` to an SDF ``<world>``: an ``<nxpcup:solid>`` element each (what the
    simulator reads back) and a Gazebo model each (:meth:`Solid.sdf`)."""
    for b in solids:
        el = ET.SubElement(world, nxpcup_tag("solid"), name=b.name)
        for key in FIELDS:
            ET.SubElement(el, nxpcup_tag(key)).text = repr(float(getattr(b, key)))
        world.append(ET.fromstring(b.sdf(surface_z_m)))


def from_sdf_world(world: ET.Element, source: str = "<world>") -> tuple[Solid, ...]:
    """The ``<nxpcup:solid>`` elements of an SDF ``<world>``; a missing or bad number raises
    :class:`worlds.WorldError` naming ``source``, the solid and what was expected (the car
    would otherwise drive through an object the world shows)."""
    from worlds.sdf_xml import WorldError

    out = []
    for el in world.findall(nxpcup_tag("solid")) + world.findall("nxpcup:solid"):
        name = el.get("name") or f"box_{len(out) + 1}"
        values = [float_of(nxpcup_child(el, key)) for key in FIELDS]
        missing = [key for key, v in zip(FIELDS, values) if v is None]
        if missing:
            raise WorldError(f"{source}: nxpcup:solid {name!r}: {missing[0]}: expected a finite number")
        try:
            out.append(Solid(name, *values))
        except ValueError as exc:
            raise WorldError(f"{source}: {exc}") from None
    return tuple(out)


def obstacle_cube(name: str, x_m: float, y_m: float, yaw_rad: float) -> Solid:
    """The obstacle discipline's white 20 cm cube (rules summary sections 1.2, 4.2)."""
    side = 0.20
    return Solid(name, x_m, y_m, side, side, side, yaw_rad, WHITE_REFLECTANCE, EPS_DENSITY_KGPM3 * side ** 3)


def braking_block(name: str, x_m: float, y_m: float, yaw_rad: float) -> Solid:
    """The emergency-braking discipline's black 20 x 20 x 60 cm block, lying across the track
    (60 cm across ``yaw_rad``, the track's direction; rules summary section 4.4)."""
    return Solid(name, x_m, y_m, 0.20, 0.60, 0.20, yaw_rad, BLACK_REFLECTANCE, EPS_DENSITY_KGPM3 * 0.2 * 0.2 * 0.6)
