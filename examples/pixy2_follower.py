"""A Pixy2 line follower of the kind NXP Cup teams write: both edge lines as Pixy2 vectors.

Run it:  simrunner drive examples/pixy2_follower.py --car examples/pixy2_car.toml [--video run.mp4]

Each frame (60 a second) it asks the Pixy2 for all its line features
(``pixy.line.getAllFeatures()``) and maps every vector's ends from the 79 x 52 line grid onto
the floor, as a team does once it has measured its camera mount (the numbers of
examples/pixy2_car.toml below). Of the lines that start near the car, the nearest one left of
the car is the left edge, the nearest right of it the right edge. It aims at the lane's middle
LOOKAHEAD_M from the rear axle - the edges it sees moved half a lane inwards - and steers
there by pure pursuit; with no edge in view it keeps its last steering. It slows down while
steering hard or when the middle farther ahead (FAR_EXTRA_M more) bends tightly. Barcodes on
the track (docs/pixy2.md, examples/barcodes.txt) cap its speed from the frame they are read:
code SLOW_CODE at ``v_min``, code FAST_CODE lifts the cap again.

Units: Spinner defaults (m/s, radians, + = left). The C++ twin: examples/pixy2_follower.cpp.
Parameters (``--param NAME=VALUE``): ``v_max``, ``v_min`` (m/s), ``lookahead`` (m).
"""
from __future__ import annotations

import math
from typing import NamedTuple

GRID_W, GRID_H = 79, 52      # the Pixy2's line grid (x 0..78, y 0..51)
CAM_HEIGHT_M = 0.30          # the camera mount (examples/pixy2_car.toml)
CAM_PITCH_RAD = 0.60
CAM_FORWARD_M = 0.20         # ahead of the rear axle
HFOV_RAD = math.radians(60.0)
WHEELBASE_M = 0.175
HALF_LANE_M = 0.265          # lane centre to an edge line's centre (rules: 550 mm over the 20 mm lines)
MIN_GAP_M = 0.35             # the other edge starts at least this far from the first (lane 0.53 m)
NEAR_M = 0.9                 # an edge line must start this close to the camera
LOOKAHEAD_M = 0.45           # the aim point's distance from the rear axle
SMOOTH = 0.5                 # low-pass factor of the steering per frame
MAX_TURN_RAD = 2.0           # an edge's vectors turn less than this in all
FAR_EXTRA_M = 0.40           # the far aim point (for the speed) is this much farther
TIGHT_RADIUS_M = 0.6         # a bend this tight ahead: the lowest speed
V_MAX_MPS = 2.2
V_MIN_MPS = 1.2
STEER_LIMIT_RAD = 0.40
SLOW_CODE, FAST_CODE = 1, 2  # barcodes: a slow zone starts / ends
_F_PX = (GRID_W / 2.0) / math.tan(HFOV_RAD / 2.0)


def to_floor(x: float, y: float) -> tuple[float, float] | None:
    """Grid point -> (ahead, left) in metres from the camera on the floor (None: above the
    horizon). Pinhole camera of simrunner.sensors.camera."""
    u, v = (x + 0.5 - GRID_W / 2.0) / _F_PX, (y + 0.5 - GRID_H / 2.0) / _F_PX
    down = math.sin(CAM_PITCH_RAD) + v * math.cos(CAM_PITCH_RAD)
    if down <= 1e-6:
        return None
    t = CAM_HEIGHT_M / down
    return t * (math.cos(CAM_PITCH_RAD) - v * math.sin(CAM_PITCH_RAD)), -t * u


def edge_chain(first, vectors) -> list:
    """``first`` and the vectors that continue it (a curved line comes as several vectors,
    each starting where the last one ends), until the line has turned by more than
    MAX_TURN_RAD in all (beyond that it is the edge of another part of the track)."""
    chain, seen, turned = [first], {first.m_index}, 0.0
    while True:
        last = chain[-1]
        nxt = next((v for v in vectors if v.m_index not in seen
                    and (v.m_x0, v.m_y0) == (last.m_x1, last.m_y1)), None)
        if nxt is None:
            return chain
        turned += bend_rad(last, nxt)
        if abs(turned) > MAX_TURN_RAD:
            return chain
        chain.append(nxt)
        seen.add(nxt.m_index)


def bend_rad(a, b) -> float:
    """Turn from vector ``a``'s direction to ``b``'s, on the floor."""
    def heading(v):
        p, q = to_floor(v.m_x0, v.m_y0), to_floor(v.m_x1, v.m_y1)
        return None if p is None or q is None else math.atan2(q[1] - p[1], q[0] - p[0])
    ha, hb = heading(a), heading(b)
    if ha is None or hb is None:
        return 0.0
    return (hb - ha + math.pi) % (2.0 * math.pi) - math.pi


def middle_points(chain, left_m: float) -> list[tuple[float, float]]:
    """The floor points of an edge chain moved ``left_m`` to its left (seen from the tail
    towards the head), in rear-axle coordinates."""
    pts = []
    for v in chain:
        a, b = to_floor(v.m_x0, v.m_y0), to_floor(v.m_x1, v.m_y1)
        if a is None or b is None:
            break
        dx, dy = b[0] - a[0], b[1] - a[1]
        n = math.hypot(dx, dy)
        if n < 1e-9:
            continue
        ox, oy = -dy / n * left_m + CAM_FORWARD_M, dx / n * left_m
        pts += [(a[0] + ox, a[1] + oy), (b[0] + ox, b[1] + oy)]
    return pts


def pursuit_point(pts, radius_m: float) -> tuple[float, float] | None:
    """Where the path through ``pts`` (its first and last pieces extended) leaves the circle
    of ``radius_m`` round the rear axle; its nearest point when it stays outside."""
    if len(pts) < 2:
        return None
    best = None
    for k in range(0, len(pts) - 1, 2):
        (x0, y0), (x1, y1) = pts[k], pts[k + 1]
        dx, dy = x1 - x0, y1 - y0
        n = math.hypot(dx, dy)
        dx, dy = dx / n, dy / n
        t_foot = -(x0 * dx + y0 * dy)
        fx, fy = x0 + t_foot * dx, y0 + t_foot * dy
        gap2 = radius_m * radius_m - (fx * fx + fy * fy)
        if gap2 <= 0.0:
            if k == 0:
                best = (fx, fy)
            continue
        t = t_foot + math.sqrt(gap2)   # leaving the circle, towards the head
        first, last = k == 0, k == len(pts) - 2
        if (t >= 0.0 or first) and (t <= n or last):
            return x0 + t * dx, y0 + t * dy
    return best


class Seg(NamedTuple):
    """A vector with its tail at its lower end (the Pixy2 may have reversed it)."""

    m_x0: int
    m_y0: int
    m_x1: int
    m_y1: int
    m_index: int


def upward(v) -> Seg:
    if (v.m_y0, -v.m_x0) < (v.m_y1, -v.m_x1):
        return Seg(v.m_x1, v.m_y1, v.m_x0, v.m_y0, v.m_index)
    return Seg(v.m_x0, v.m_y0, v.m_x1, v.m_y1, v.m_index)


def lane_edges(vectors):
    """The left and the right edge line as vector chains (or None): the vector whose tail is
    nearest the camera (within NEAR_M) starts the edge on its side; the nearest one on the
    other side that starts at least MIN_GAP_M from that chain starts the other edge."""
    vectors = [upward(v) for v in vectors]
    near = []
    for v in vectors:
        tail = to_floor(v.m_x0, v.m_y0)
        if tail is not None and tail[0] <= NEAR_M:
            near.append((math.hypot(*tail), v.m_index, tail, v))
    near.sort(key=lambda n: n[:2])
    edges: dict[bool, list] = {}
    points: list[tuple[float, float]] = []
    for _dist, _index, tail, v in near:
        is_left = tail[1] >= 0.0
        if is_left in edges or any(math.dist(tail, p) < MIN_GAP_M for p in points):
            continue
        edges[is_left] = chain = edge_chain(v, vectors)
        points += [p for c in chain for p in (to_floor(c.m_x0, c.m_y0), to_floor(c.m_x1, c.m_y1))
                   if p is not None]
    return edges.get(True), edges.get(False)


def curvature(points) -> float:
    """Curvature (1/m, + = left) of the arc from the rear axle, heading ahead, through the
    mean of ``points``."""
    x = sum(p[0] for p in points) / len(points)
    y = sum(p[1] for p in points) / len(points)
    return 2.0 * y / (x * x + y * y)


def main(spinner):
    pixy = spinner.pixy2()
    pixy.init()
    pixy.changeProg("line")
    v_max = spinner.param("v_max", V_MAX_MPS)
    v_min = spinner.param("v_min", V_MIN_MPS)
    look = spinner.param("lookahead", LOOKAHEAD_M)
    steer, cap = 0.0, v_max
    while True:
        pixy.line.getAllFeatures()
        for code in pixy.line.barcodes:
            cap = v_min if code.m_code == SLOW_CODE else v_max if code.m_code == FAST_CODE else cap
        left, right = lane_edges(pixy.line.vectors)
        aims, fars = [], []  # the lane's middle from each edge in view: near and far aim points
        for chain, inward in ((left, -HALF_LANE_M), (right, HALF_LANE_M)):
            if chain is not None:
                middle = middle_points(chain, inward)
                for out, radius in ((aims, look), (fars, look + FAR_EXTRA_M)):
                    p = pursuit_point(middle, radius)
                    if p is not None:
                        out.append(p)
        aim = None
        if aims:  # pure pursuit: the arc through the rear axle and the aim point
            aim = curvature(aims)
            steer += SMOOTH * (math.atan(WHEELBASE_M * aim) - steer)
        steer = max(-STEER_LIMIT_RAD, min(STEER_LIMIT_RAD, steer))
        bend = max(abs(steer) / STEER_LIMIT_RAD, min(1.0, abs(curvature(fars)) * TIGHT_RADIUS_M) if fars else 0.0)
        speed = min(cap, v_max - (v_max - v_min) * bend)
        spinner.set_speed_and_servo(speed, steer)
        if spinner.recording:
            spinner.add_data([f"vectors {pixy.line.numVectors}",
                              f"edges {'L' if left else '-'}{'R' if right else '-'}",
                              f"curvature {'-' if aim is None else f'{aim:+.2f} 1/m'}",
                              f"steer {steer:+.2f}"])
