"""The ground's height: the hills of a track (HILL pieces) as one height function and one ray cast.

Frames (docs/DESIGN.md): world x, y as the track's; heights ``z`` in metres above the track's
flat surface (the top of its slab, ``SimTrack.surface_z_m``).

A :class:`Hill` is a straight stretch of road, ``length_m`` long (measured on the floor, so a
layout chains as if it were flat) and ``width_m`` wide (the road), lifted by the raised-cosine
profile ``h(u) = H (1 - cos(2 pi u / L)) / 2`` of ``u`` (0 .. L from its entry), the same across
the road: up, crest at ``L / 2``, down, back to the floor. Its slope is zero at both ends (the
road bends onto the floor without a kink), steepest ``pi H / L`` at ``u = L / 4`` and
``3 L / 4``; the crest's radius of curvature is ``L^2 / (2 pi^2 H)`` (the hollows' at the feet
are the same). The rules allow "inclines, declines and tunnels" (2018/19) but give no slope
or size (../shared/reference/nxp-cup-rules.md, sections 1.1 and the list of what no source
gives): the profile and the defaults of the HILL piece are ours.

:class:`Terrain` holds the hills of a track: :meth:`Terrain.height_m` (the highest hill at
each point, 0 elsewhere) and :meth:`Terrain.ray_cast` (where camera rays meet the ground: the
flat floor or a hill's top; a hill hides what lies behind its crest). Pure NumPy: the physics
(:mod:`simrunner.car.physics`), the cameras (:mod:`simrunner.sensors.camera`) and the track
meshes (:mod:`trackgen.export`) use the same function.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

#: Ray-cast sampling (:meth:`Terrain.ray_cast`): a ray's height above a hill is sampled along the
#: ground at steps over which the hill's profile sags at most RAY_SAG_M from its chord
#: (``sqrt(8 RAY_SAG_M R)`` for the crest radius R; 4 cm on the default hill, at most
#: RAY_STEP_MAX_M), so a ray grazing a crest deeper than that is not missed; the crossing found
#: is then refined by regula falsi to far below a millimetre.
RAY_SAG_M = 2e-4
RAY_STEP_MAX_M = 0.05
_REFINE = 1


@dataclass(frozen=True)
class Hill:
    """One hill (module docstring): entry at world ``(x_m, y_m)`` (the middle of the road's
    entry edge), running along ``yaw_rad``; ``length_m`` on the floor, ``height_m`` at the
    crest, ``width_m`` across."""

    x_m: float
    y_m: float
    yaw_rad: float
    length_m: float
    height_m: float
    width_m: float

    def __post_init__(self) -> None:
        for name in ("x_m", "y_m", "yaw_rad", "length_m", "height_m", "width_m"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"Hill: {name} = {v!r}: expected a finite number")
            object.__setattr__(self, name, float(v))
        if min(self.length_m, self.height_m, self.width_m) <= 0.0:
            raise ValueError(f"Hill: length_m, height_m and width_m must be > 0, got "
                             f"{self.length_m}, {self.height_m}, {self.width_m}")

    # -- the profile -----------------------------------------------------------------
    def profile_m(self, u_m):
        """Height (m) at ``u_m`` metres from the entry (0 outside ``0 .. length_m``)."""
        u = np.asarray(u_m, dtype=float)
        inside = (u >= 0.0) & (u <= self.length_m)
        h = 0.5 * self.height_m * (1.0 - np.cos((2.0 * math.pi / self.length_m) * u))
        return np.where(inside, h, 0.0)

    def slope(self, u_m):
        """``dh/du`` at ``u_m`` (0 outside the hill)."""
        u = np.asarray(u_m, dtype=float)
        k = 2.0 * math.pi / self.length_m
        inside = (u >= 0.0) & (u <= self.length_m)
        return np.where(inside, 0.5 * self.height_m * k * np.sin(k * u), 0.0)

    @property
    def max_slope_rad(self) -> float:
        """The steepest angle of the road on the hill (at a quarter and three quarters)."""
        return math.atan(math.pi * self.height_m / self.length_m)

    @property
    def crest_radius_m(self) -> float:
        """Radius of curvature at the crest (and at the two feet), m."""
        return self.length_m ** 2 / (2.0 * math.pi ** 2 * self.height_m)

    # -- frames ----------------------------------------------------------------------
    def local(self, x_m, y_m):
        """World points -> ``(u, v)``: along the hill from its entry, and to its left."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        dx = np.asarray(x_m, dtype=float) - self.x_m
        dy = np.asarray(y_m, dtype=float) - self.y_m
        return c * dx + s * dy, -s * dx + c * dy

    def height_at_m(self, x_m, y_m):
        """Height (m) of this hill's top at world points (0 off its footprint)."""
        u, v = self.local(x_m, y_m)
        return np.where(np.abs(v) <= 0.5 * self.width_m, self.profile_m(u), 0.0)

    def corners_xy(self) -> np.ndarray:
        """``(4, 2)`` world corners of the footprint (entry left, exit left, exit right, entry right)."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        hw = 0.5 * self.width_m
        local = np.array([[0.0, hw], [self.length_m, hw], [self.length_m, -hw], [0.0, -hw]])
        return np.array([self.x_m, self.y_m]) + local @ np.array([[c, s], [-s, c]])

    def solid_arrays(self, step_m: float = 0.02, base_m: float = -0.005):
        """A closed triangle mesh of the hill as a solid (for a physics engine): its top the
        profile sampled every ``step_m`` or less along the road (flat across), its bottom at
        height ``base_m``; ``(vertices (V, 3) world metres, heights above the surface; faces
        (F, 3) int64, outward normals)``."""
        n = max(2, int(math.ceil(self.length_m / step_m)))
        u = np.linspace(0.0, self.length_m, n + 1)
        top = self.profile_m(u)
        hw = 0.5 * self.width_m
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        # per station: top left, top right, bottom left, bottom right
        uu = np.repeat(u, 4)
        vv = np.tile([hw, -hw, hw, -hw], n + 1)
        zz = np.column_stack([top, top, np.full(n + 1, base_m), np.full(n + 1, base_m)]).ravel()
        verts = np.column_stack([self.x_m + c * uu - s * vv, self.y_m + s * uu + c * vv, zz])
        a = 4 * np.arange(n)
        b = a + 4
        faces = [np.column_stack([(a, b)[j] + k for j, k in tri]) for tri in (
            ((0, 0), (0, 1), (1, 1)), ((0, 0), (1, 1), (1, 0)),   # top
            ((0, 2), (1, 2), (1, 3)), ((0, 2), (1, 3), (0, 3)),   # bottom
            ((0, 0), (1, 0), (1, 2)), ((0, 0), (1, 2), (0, 2)),   # left side
            ((0, 1), (0, 3), (1, 3)), ((0, 1), (1, 3), (1, 1)))]  # right side
        e = 4 * n
        faces.append(np.array([[0, 2, 3], [0, 3, 1], [e, e + 1, e + 3], [e, e + 3, e + 2]]))
        return verts, np.vstack(faces).astype(np.int64)

    # -- track.json ------------------------------------------------------------------
    def to_json(self) -> dict:
        return {"x_m": self.x_m, "y_m": self.y_m, "yaw_rad": self.yaw_rad, "length_m": self.length_m,
                "height_m": self.height_m, "width_m": self.width_m}

    @classmethod
    def from_json(cls, doc) -> "Hill":
        """From :meth:`to_json`'s dict; raises ValueError naming what is missing or wrong."""
        if not isinstance(doc, dict):
            raise ValueError(f"a hill: expected an object, got {type(doc).__name__}")
        names = ("x_m", "y_m", "yaw_rad", "length_m", "height_m", "width_m")
        missing = [n for n in names if n not in doc]
        if missing:
            raise ValueError(f"a hill: missing {', '.join(missing)}")
        return cls(*(doc[n] for n in names))


@dataclass(frozen=True)
class Terrain:
    """The hills of a track (module docstring); empty = the flat floor."""

    hills: tuple[Hill, ...] = ()

    def __bool__(self) -> bool:
        return bool(self.hills)

    def widened(self, margin_m: float) -> "Terrain":
        """The same hills ``margin_m`` wider on both sides (their profiles unchanged): a road's
        edge vertices fall inside them, whatever the rounding."""
        return Terrain(tuple(replace(h, width_m=h.width_m + 2.0 * margin_m) for h in self.hills))

    @property
    def max_height_m(self) -> float:
        return max((h.height_m for h in self.hills), default=0.0)

    def height_m(self, x_m, y_m):
        """Ground height (m) at world points: the highest hill there, 0 elsewhere."""
        out = np.zeros(np.broadcast(np.asarray(x_m), np.asarray(y_m)).shape)
        for hill in self.hills:
            out = np.maximum(out, hill.height_at_m(x_m, y_m))
        return out

    def ray_cast(self, origin, dirs, max_t: np.ndarray | float = np.inf):
        """Where rays from ``origin`` ``(3,)`` (world x, y and height above the surface) along
        ``dirs`` ``(..., 3)`` first meet the ground: the ray parameter ``t`` (``origin + t dirs``),
        ``inf`` where a ray meets nothing before ``max_t``. The floor is the plane ``z = 0``; a
        hill is its top and the two upright sides of its slab (it hides what is behind)."""
        o = np.asarray(origin, dtype=float)
        d = np.asarray(dirs, dtype=float)
        shape = d.shape[:-1]
        d = d.reshape(-1, 3)
        dx, dy, dz = d[:, 0], d[:, 1], d[:, 2]
        max_t = np.broadcast_to(max_t, shape).reshape(-1)
        down = dz < 0.0
        t = np.full(dz.shape, np.inf)
        t[down] = o[2] / -dz[down]
        t[~(t <= max_t)] = np.inf
        for hill in self.hills:
            t = np.minimum(t, _hill_hit(hill, o, dx, dy, dz, np.fmin(t, max_t)))
        return t.reshape(shape)


def _slab(o: float, d: np.ndarray, lo: float, hi: float):
    """Ray parameter interval inside ``lo <= o + t d <= hi`` (per ray; empty when lo > hi). A
    ray parallel to the slab (``d = 0``) gets ``(-inf, inf)`` inside it and an empty interval
    outside (``1 / 0 = inf``; ``fmin``/``fmax`` skip the NaN of a ray exactly on its border)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1 = (lo - o) * inv
        t2 = (hi - o) * inv
    return np.fmin(t1, t2), np.fmax(t1, t2)


def _hill_hit(hill: Hill, o: np.ndarray, dx: np.ndarray, dy: np.ndarray, dz: np.ndarray,
              t_end: np.ndarray) -> np.ndarray:
    """First ``t`` in ``[0, t_end]`` where the rays (flat arrays of their direction's components)
    meet ``hill`` (inf where they do not): the ray's height above the hill sampled along the
    ground (steps over which the profile sags ``RAY_SAG_M`` at most) from where it enters the
    hill's footprint to where it leaves it, the first crossing refined by regula falsi; a ray
    below the hill's top where it enters meets its side (or end) there."""
    c, s = math.cos(hill.yaw_rad), math.sin(hill.yaw_rad)
    ox, oy = o[0] - hill.x_m, o[1] - hill.y_m
    ou, ov = c * ox + s * oy, c * oy - s * ox
    du = c * dx + s * dy
    dv = c * dy - s * dx
    u_lo, u_hi = _slab(ou, du, 0.0, hill.length_m)
    v_lo, v_hi = _slab(ov, dv, -0.5 * hill.width_m, 0.5 * hill.width_m)
    t_in = np.fmax(np.fmax(u_lo, v_lo), 0.0)
    t_out = np.fmin(np.fmin(u_hi, v_hi), t_end)
    out = np.full(dz.shape, np.inf)
    idx = np.flatnonzero(t_in < t_out)
    if not idx.size:
        return out
    t0, t1 = t_in[idx], t_out[idx]
    ru, rz = du[idx], dz[idx]
    k = 2.0 * math.pi / hill.length_m
    half = 0.5 * hill.height_m
    oz_half = o[2] - half

    def gap(tt, ru, rz):  # the ray's height above the hill's top (tt inside the footprint: the
        g = ou + tt * ru    # profile's formula is smooth to zero at both of its ends)
        g *= k
        np.cos(g, out=g)
        g *= half
        g += oz_half
        g += tt * rz
        return g

    dt = t1 - t0
    span = float((dt * np.hypot(ru, dv[idx])).max())
    step = min(RAY_STEP_MAX_M, math.sqrt(8.0 * RAY_SAG_M * hill.crest_radius_m))
    n = max(2, int(math.ceil(span / step)) + 1)
    ts = t0[:, None] + dt[:, None] * (np.arange(n) / (n - 1))[None, :]
    g = gap(ts, ru[:, None], rz[:, None])
    below = g <= 0.0
    first = below.argmax(axis=1)
    rows = np.flatnonzero(below[np.arange(len(idx)), first])
    if not rows.size:
        return out
    first = first[rows]
    hit = ts[rows, first]
    inner = first > 0
    if inner.any():
        j, f = rows[inner], first[inner]
        a, b = ts[j, f - 1], ts[j, f]
        ga, gb = g[j, f - 1], g[j, f]
        for _ in range(_REFINE):  # regula falsi: keeps the crossing bracketed
            m = b - gb * (b - a) / (gb - ga)
            gm = gap(m, ru[j], rz[j])
            up = gm > 0.0
            a, ga = np.where(up, m, a), np.where(up, gm, ga)
            b, gb = np.where(up, b, m), np.where(up, gb, gm)
        hit[inner] = b - gb * (b - a) / (gb - ga)
    out[idx[rows]] = hit
    return out
