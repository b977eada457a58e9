"""Pixy2 line tracking, emulated from the camera's frame: vectors, intersections, tracking.

What the Pixy2 reports in its line-tracking program (docs.pixycam.com, "Line tracking" and
"Line tracking API", wiki v2), computed by our own rules from the simulated frame
(docs/pixy2.md says what is emulated and what is not):

1. **Grid.** The camera frame (``camera.width_px x camera.height_px``, 316 x 208 on the Pixy2)
   is averaged over blocks to the line grid (``pixy2.grid_width_px x grid_height_px``,
   79 x 52); vector coordinates are grid pixels, x right, y down, (0, 0) the top left (the
   far left of the view). The white-line mode inverts the grid.
2. **Line points.** Every grid row is scanned left to right and every column top to bottom
   with an edge detector: the step ``g[i] = p[i + d] - p[i]`` (``d = edge_distance_px``). A
   run of ``g <= -edge_threshold`` is a falling edge (light to dark), a run of
   ``g >= edge_threshold`` a rising one; each edge sits at its run's ``|g|``-weighted centre
   plus ``d / 2``. A falling edge followed by a rising one ``min_line_width_px`` to
   ``max_line_width_px`` later is a dark line crossing the scan: a line point half-way.
   A dark area wider than ``max_line_width_px`` (the floor beside the track, a crossing's
   square) gives no point.
3. **Lines.** Points of neighbouring rows (columns) within 2 px (3 px across one missed
   scan) chain up; a row chain keeps only its steep parts (at most 45 degrees from
   vertical), a column chain its flat parts (less than 45 degrees), so every piece of line is
   found once. Chain ends within ``max_merge_distance_px`` meet in a node; at a node of two
   ends that bend less than 45 degrees the chains join into one line. A line's vector goes
   from one end to the other (a curved line gives its chord); lines shorter than
   ``min_line_length_px`` are dropped.
4. **Intersections.** A node where 3 or more lines meet (at most 6 reported with it). Each
   line's angle is in degrees, 0 = straight on along the reference direction, positive =
   left: the Vector's direction when the Vector leads into the intersection, else straight
   up the image.
5. **Direction and tracking.** A vector's tail is its lower end (nearer the car; the left
   end of a level line), its head the upper one. A line keeps its index (0-255) from the last
   frame when both its ends moved at most ``max_line_compare_px``; new lines take the next
   free index.
6. **The Vector** (``getMainFeatures``): the line tracked as the Vector in the last frame
   while it is seen; else the branch chosen at the last intersection; else the line whose
   tail is nearest the bottom centre of the grid among those whose tail is in the lower half.
   When the Vector leads into an intersection, the vector carries
   ``LINE_FLAG_INTERSECTION_PRESENT``, the intersection is reported, and the branch whose
   angle is nearest the next turn (``setNextTurn``, once; else ``setDefaultTurn``, 0 =
   straight on) becomes the Vector when the old one is lost or the intersection is in the
   bottom fifth of the grid. Manual mode (``LINE_MODE_MANUAL_SELECT_VECTOR``) keeps the
   index set with ``setVector``; ``reverseVector`` swaps the Vector's head and tail from then
   on.

Everything is deterministic: the same frame and state give the same features.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from simrunner.errors import CameraError
from simrunner.sensors.pixy2_codes import cleared, edge_centres, find_codes

LINE_VECTOR, LINE_INTERSECTION, LINE_BARCODE = 0x01, 0x02, 0x04
LINE_ALL_FEATURES = LINE_VECTOR | LINE_INTERSECTION | LINE_BARCODE
LINE_MODE_TURN_DELAYED, LINE_MODE_MANUAL_SELECT_VECTOR, LINE_MODE_WHITE_LINE = 0x01, 0x02, 0x80
LINE_FLAG_INVALID, LINE_FLAG_INTERSECTION_PRESENT = 0x02, 0x04
LINE_MAX_INTERSECTION_LINES = 6
PIXY_RESULT_OK, PIXY_RESULT_ERROR, PIXY_RESULT_BUSY = 0, -1, -2

_LINK_PX = 2.0        # chain: largest step between points of neighbouring scans
_LINK_GAP_PX = 3.0    # ... across one scan without a point
_JOIN_COS = math.cos(math.radians(135.0))  # ends of a degree-2 node join when they bend < 45 deg
_DIR_PX = 4.0         # how far along a line its direction at an end is measured
_TURN_ROW = 0.8       # the intersection in the bottom fifth: the chosen branch takes over
_BEND_PX = 1.5        # a line is cut into straight vectors where it strays farther from the chord


@dataclass(frozen=True)
class Vector:
    """A line: tail ``(m_x0, m_y0)``, head ``(m_x1, m_y1)`` in grid pixels, tracking index,
    flags (Pixy2Line.h names)."""

    m_x0: int
    m_y0: int
    m_x1: int
    m_y1: int
    m_index: int
    m_flags: int = 0


@dataclass(frozen=True)
class IntersectionLine:
    """One line of an intersection: its tracking index and angle (degrees, + = left)."""

    m_index: int
    m_angle: int


@dataclass(frozen=True)
class Intersection:
    """Where 3 or more lines meet: position (grid pixels), number of lines, the lines."""

    m_x: int
    m_y: int
    m_n: int
    m_intLines: tuple[IntersectionLine, ...]


@dataclass(frozen=True)
class Barcode:
    """A barcode read in the frame: its centre (grid pixels), flags, its code 0-15
    (:mod:`simrunner.sensors.pixy2_codes`)."""

    m_x: int
    m_y: int
    m_flags: int
    m_code: int


@dataclass(frozen=True)
class Features:
    """One frame's features."""

    vectors: tuple[Vector, ...] = ()
    intersections: tuple[Intersection, ...] = ()
    barcodes: tuple[Barcode, ...] = ()


# -- 1. grid ------------------------------------------------------------------------------
def grid_image(frame: np.ndarray, grid_w: int, grid_h: int) -> np.ndarray:
    """The ``(grid_h, grid_w)`` float64 block mean of a ``(H, W)`` frame whose sides are whole
    multiples of the grid's (else :class:`CameraError`)."""
    h, w = frame.shape
    if h % grid_h or w % grid_w:
        raise CameraError(f"the Pixy2 line grid {grid_w} x {grid_h} needs a camera frame whose width "
                          f"and height are whole multiples of it, got {w} x {h} (camera.width_px, "
                          f"camera.height_px; a Pixy2 car: examples/pixy2_car.toml)")
    by, bx = h // grid_h, w // grid_w
    return frame.astype(np.float64).reshape(grid_h, by, grid_w, bx).mean(axis=(1, 3))


# -- 2. line points -------------------------------------------------------------------------
def scan_lines(profiles: np.ndarray, *, threshold: float, d: int, min_w: float,
               max_w: float) -> list[list[float]]:
    """Line points along each scan (row of ``profiles``): a dark run between a falling and a
    rising edge, ``min_w`` to ``max_w`` wide."""
    g = profiles[:, d:] - profiles[:, :-d]
    falls = edge_centres(g, g <= -threshold, d)
    rises = edge_centres(g, g >= threshold, d)
    out = []
    for f_row, r_row in zip(falls, rises):
        points: list[float] = []
        if f_row and r_row:
            events = sorted([(x, 0) for x in f_row] + [(x, 1) for x in r_row])
            fall = None
            for x, kind in events:
                if kind == 0:
                    fall = x
                elif fall is not None:
                    if min_w <= x - fall <= max_w:
                        points.append((fall + x) / 2.0)
                    fall = None
        out.append(points)
    return out


def scan_points(profile: np.ndarray, *, threshold: float, d: int, min_w: float, max_w: float) -> list[float]:
    """Line points along one scan (:func:`scan_lines` of one row)."""
    return scan_lines(np.asarray(profile, dtype=np.float64)[None, :], threshold=threshold, d=d,
                      min_w=min_w, max_w=max_w)[0]


# -- 3. lines ---------------------------------------------------------------------------------
def _chains(scans: list[list[float]]) -> list[list[tuple[float, int]]]:
    """Chain points ``(position, scan)`` of neighbouring scans (closest pairs first)."""
    done: list[list[tuple[float, int]]] = []
    open_: list[list[tuple[float, int]]] = []
    for s, pts in enumerate(scans):
        pairs = []
        for ci, ch in enumerate(open_):
            pos, last = ch[-1]
            limit = _LINK_PX if last == s - 1 else _LINK_GAP_PX
            for pi, p in enumerate(pts):
                dist = abs(p - pos)
                if dist <= limit:
                    pairs.append((dist, ci, pi))
        pairs.sort()
        used_c, used_p = set(), set()
        for _dist, ci, pi in pairs:
            if ci in used_c or pi in used_p:
                continue
            used_c.add(ci)
            used_p.add(pi)
            open_[ci].append((pts[pi], s))
        for pi, p in enumerate(pts):
            if pi not in used_p:
                open_.append([(p, s)])
        still = []
        for ch in open_:
            (still if ch[-1][1] >= s - 1 else done).append(ch)
        open_ = still
    return done + open_


def _pieces(chain: list[tuple[float, int]], steep: bool) -> list[np.ndarray]:
    """The parts of a chain at most 45 deg from its scan's normal (``steep``: <= 1 px per
    scan, else < 1 px), as ``(n, 2)`` arrays of ``(along_scan, scan)``."""
    pts = np.array(chain, dtype=np.float64)
    n = len(pts)
    if n < 2:
        return []
    ok = np.empty(n, dtype=bool)
    for i in range(n):
        a, b = max(0, i - 2), min(n - 1, i + 2)
        slope = abs(pts[b, 0] - pts[a, 0]) / max(pts[b, 1] - pts[a, 1], 1e-9)
        ok[i] = slope <= 1.0 if steep else slope < 1.0
    out, start = [], None
    for i in range(n + 1):
        if i < n and ok[i]:
            start = i if start is None else start
        elif start is not None:
            if i - start >= 2:
                out.append(pts[start:i])
            start = None
    return out


@dataclass
class _Line:
    pts: np.ndarray                 # (n, 2) grid x, y along the line
    ends: list = field(default_factory=lambda: [None, None])  # node id at each end

    def direction_at(self, end: int) -> np.ndarray:
        """Unit direction from end ``end`` into the line (measured ``_DIR_PX`` along it)."""
        p = self.pts if end == 0 else self.pts[::-1]
        d = np.linalg.norm(p - p[0], axis=1)
        k = int(np.argmax(d >= _DIR_PX)) if (d >= _DIR_PX).any() else len(p) - 1
        v = p[k] - p[0]
        nv = float(np.hypot(*v))
        return v / nv if nv > 0 else np.array([0.0, -1.0])


def _pieces_of(grid: np.ndarray, spec, white_line: bool, clear=()) -> list[np.ndarray]:
    """Straight pieces of line, ``(N, 2)`` grid points each; no points inside the ``clear``
    rectangles ``(x0, x1, y0, y1)`` (barcodes)."""
    g = 255.0 - grid if white_line else grid
    kw = dict(threshold=float(spec.edge_threshold), d=int(spec.edge_distance_px),
              min_w=float(spec.min_line_width_px), max_w=float(spec.max_line_width_px))
    rows = scan_lines(g, **kw)
    cols = scan_lines(np.ascontiguousarray(g.T), **kw)
    for x0, x1, y0, y1 in clear:
        rows = [[x for x in pts if not (x0 <= x <= x1 and y0 <= y <= y1)] for y, pts in enumerate(rows)]
        cols = [[y for y in pts if not (x0 <= x <= x1 and y0 <= y <= y1)] for x, pts in enumerate(cols)]
    pieces = []
    for ch in _chains(rows):
        pieces += _pieces(ch, steep=True)                               # (x, y)
    for ch in _chains(cols):
        pieces += [p[:, ::-1].copy() for p in _pieces(ch, steep=False)]  # (y, x) -> (x, y)
    return pieces


def _graph(pieces: list[np.ndarray], merge_px: float):
    """Lines (pieces joined at straight-on degree-2 nodes) and node positions."""
    ends = [(i, e, p[0] if e == 0 else p[-1]) for i, p in enumerate(pieces) for e in (0, 1)]
    parent = list(range(len(ends)))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a
    for a in range(len(ends)):
        for b in range(a + 1, len(ends)):
            if ends[a][0] != ends[b][0] and np.hypot(*(ends[a][2] - ends[b][2])) <= merge_px:
                ra, rb = find(a), find(b)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
    lines = [_Line(p.copy()) for p in pieces]
    members: dict[int, list[tuple[int, int]]] = {}
    for k, (i, e, _p) in enumerate(ends):
        members.setdefault(find(k), []).append((i, e))
    nodes: dict[int, np.ndarray] = {}
    for root, mem in members.items():
        if len(mem) > 1:
            nodes[root] = np.mean([ends[2 * i + e][2] for i, e in mem], axis=0)
            for i, e in mem:
                lines[i].ends[e] = root
    # join the two lines of a degree-2 node that go on nearly straight
    for root in sorted(nodes):
        at = [(i, e) for i, ln in enumerate(lines) if ln is not None for e in (0, 1) if ln.ends[e] == root]
        if len(at) != 2 or at[0][0] == at[1][0]:
            continue
        (i, ei), (j, ej) = at
        if float(lines[i].direction_at(ei) @ lines[j].direction_at(ej)) > _JOIN_COS:
            continue
        a = lines[i].pts if ei == 1 else lines[i].pts[::-1]     # ... -> node
        b = lines[j].pts if ej == 0 else lines[j].pts[::-1]     # node -> ...
        far_a, far_b = lines[i].ends[1 - ei], lines[j].ends[1 - ej]
        lines[i] = _Line(np.vstack((a, b)), [far_a, far_b])
        lines[j] = None
    return [ln for ln in lines if ln is not None], nodes


def _split(pts: np.ndarray, tol_px: float) -> list[np.ndarray]:
    """Douglas-Peucker: ``pts`` cut into pieces that stray at most ``tol_px`` from their
    chords (neighbouring pieces share their cut point)."""
    a, b = pts[0], pts[-1]
    if len(pts) <= 2:
        return [pts]
    d = b - a
    n = float(np.hypot(*d))
    off = (np.abs(d[0] * (pts[:, 1] - a[1]) - d[1] * (pts[:, 0] - a[0])) / n if n > 0
           else np.hypot(*(pts - a).T))
    k = int(np.argmax(off))
    if off[k] <= tol_px or k in (0, len(pts) - 1):
        return [pts]
    return _split(pts[:k + 1], tol_px) + _split(pts[k:], tol_px)


def _straight(lines: list[_Line]) -> list[_Line]:
    """Curved lines cut into straight pieces (the cut points are ends without a node)."""
    out = []
    for ln in lines:
        parts = _split(ln.pts, _BEND_PX)
        for j, p in enumerate(parts):
            out.append(_Line(p, [ln.ends[0] if j == 0 else None,
                                 ln.ends[1] if j == len(parts) - 1 else None]))
    return out


def _angle_deg(ref: np.ndarray, d: np.ndarray) -> float:
    """Angle from ``ref`` to ``d`` in image coordinates (y down), + = left of ``ref``."""
    cross = ref[0] * d[1] - ref[1] * d[0]
    return math.degrees(math.atan2(-cross, float(ref @ d)))


def _px(v: float, hi: int) -> int:
    return int(min(max(round(v), 0), hi))


# -- 5., 6. the tracker ------------------------------------------------------------------------
@dataclass
class _Seg:
    """A line of the frame in progress, oriented: tail and head (node positions where the
    line ends in a node), their node ids, the line."""

    tail: np.ndarray
    head: np.ndarray
    tail_node: int | None
    head_node: int | None
    line: _Line
    tail_end: int  # which end of ``line`` is the tail

    def reverse(self) -> "_Seg":
        return _Seg(self.head, self.tail, self.head_node, self.tail_node, self.line, 1 - self.tail_end)


class LineTracker:
    """Line tracking of one Pixy2 over a run: ``spec`` is the car's ``pixy2`` section.
    :meth:`process` turns a frame into features and updates the tracking; the attributes
    ``mode``, ``default_turn_deg``, ``next_turn_deg``, ``manual_index`` follow the Pixy2
    API's setters, :meth:`reverse_vector` its ``reverseVector``."""

    def __init__(self, spec) -> None:
        self.spec = spec
        self.w = int(spec.grid_width_px)
        self.h = int(spec.grid_height_px)
        self.mode = 0
        self.default_turn_deg = 0
        self.next_turn_deg: int | None = None
        self.manual_index: int | None = None
        self._reversed: set[int] = set()
        self._prev: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # index -> (tail, head)
        self._counter = 0
        self.vector_index: int | None = None    # the Vector's tracking index
        self.pending_index: int | None = None   # the branch chosen at the Vector's intersection
        self._pending_at = np.zeros(2)          # ... and where that intersection was
        self.all = Features()                   # the last frame's features (getAllFeatures)
        self.main = Features()                  # ... and its main features (getMainFeatures)

    # -- one frame ----------------------------------------------------------------------
    def process(self, frame: np.ndarray) -> Features:
        """Features of ``frame`` (all of them; :attr:`main` holds the main ones)."""
        spec = self.spec
        grid = grid_image(frame, self.w, self.h)
        fh, fw = frame.shape
        sx, sy = self.w / fw, self.h / fh
        codes = find_codes(frame, threshold=float(spec.barcode_edge_threshold), d=int(spec.barcode_edge_distance_px),
                           row_step=max(1, fh // (2 * self.h)))
        gx, gy = (lambda f: (f + 0.5) * sx - 0.5), (lambda f: (f + 0.5) * sy - 0.5)  # frame -> grid px
        clear = [(gx(x0), gx(x1), gy(y0), gy(y1)) for x0, x1, y0, y1 in map(cleared, codes)]
        barcodes = tuple(Barcode(_px(gx(c.centre_px[0]), self.w - 1), _px(gy(c.centre_px[1]), self.h - 1), 0, c.code)
                         for c in codes)
        pieces = _pieces_of(grid, spec, bool(self.mode & LINE_MODE_WHITE_LINE), clear)
        lines, nodes = _graph(pieces, float(spec.max_merge_distance_px))
        lines = _straight([ln for ln in lines
                           if np.hypot(*(ln.pts[-1] - ln.pts[0])) >= float(spec.min_line_length_px)])
        degree: dict[int, int] = {}
        for ln in lines:
            for n in ln.ends:
                if n is not None:
                    degree[n] = degree.get(n, 0) + 1

        def end_pos(ln: _Line, e: int) -> np.ndarray:
            n = ln.ends[e]
            return nodes[n] if n is not None else (ln.pts[0] if e == 0 else ln.pts[-1])

        segs = []
        for ln in lines:
            p0, p1 = end_pos(ln, 0), end_pos(ln, 1)
            te = 0 if (p0[1], -p0[0]) > (p1[1], -p1[0]) else 1
            segs.append(_Seg(end_pos(ln, te), end_pos(ln, 1 - te), ln.ends[te], ln.ends[1 - te], ln, te))
        indices = self._track([(s.tail, s.head) for s in segs])
        by_index = {k: (s.reverse() if k in self._reversed else s) for k, s in zip(indices, segs)}
        self._reversed &= set(by_index)
        inter_nodes = sorted(n for n, d in degree.items() if d >= 3)
        k = self._choose(by_index, nodes, set(inter_nodes))
        vec = by_index.get(k) if k is not None else None
        ref_node = vec.head_node if vec is not None else None
        ref_dir = (vec.head - vec.tail) if vec is not None else None

        def vector(i: int) -> Vector:
            s = by_index[i]
            flags = LINE_FLAG_INTERSECTION_PRESENT if s.head_node in inter_nodes else 0
            return Vector(_px(s.tail[0], self.w - 1), _px(s.tail[1], self.h - 1),
                          _px(s.head[0], self.w - 1), _px(s.head[1], self.h - 1), i, flags)

        def intersection(n: int) -> Intersection:
            ref = ref_dir if n == ref_node else np.array([0.0, -1.0])
            ref = ref / max(float(np.hypot(*ref)), 1e-12)
            out = []
            for i in sorted(by_index):
                s = by_index[i]
                for node, end in ((s.tail_node, s.tail_end), (s.head_node, 1 - s.tail_end)):
                    if node == n:
                        out.append(IntersectionLine(i, int(round(_angle_deg(ref, s.line.direction_at(end))))))
            out = out[:LINE_MAX_INTERSECTION_LINES]
            return Intersection(_px(nodes[n][0], self.w - 1), _px(nodes[n][1], self.h - 1), len(out), tuple(out))

        self.all = Features(tuple(vector(i) for i in sorted(by_index)),
                            tuple(intersection(n) for n in inter_nodes), barcodes)
        nearest = (max(barcodes, key=lambda b: (b.m_y, -abs(b.m_x - self.w / 2.0))),) if barcodes else ()
        if vec is None:
            self.main = Features((), (), nearest)
        else:
            self.main = Features((vector(k),), (intersection(ref_node),) if ref_node in inter_nodes else (),
                                 nearest)
            self._choose_branch(by_index, k, ref_node, inter_nodes)
        return self.all

    def _choose(self, by_index: dict[int, _Seg], nodes: dict[int, np.ndarray], inter: set[int]) -> int | None:
        """The Vector's index for this frame (module docstring, 6.)."""
        if self.mode & LINE_MODE_MANUAL_SELECT_VECTOR and self.manual_index in by_index:
            k = self.manual_index
        elif self.vector_index in by_index:
            k = self.vector_index
            s = by_index[k]
            if (self.pending_index in by_index and s.head_node in inter
                    and nodes[s.head_node][1] >= _TURN_ROW * (self.h - 1)):
                k = self._take_pending(by_index)
        elif self.pending_index in by_index:
            k = self._take_pending(by_index)
        else:
            low = [(float((s.tail[0] - (self.w - 1) / 2.0) ** 2 + (self.h - 1 - s.tail[1]) ** 2), i)
                   for i, s in by_index.items() if s.tail[1] >= (self.h - 1) / 2.0]
            k = min(low)[1] if low else None
        if self.pending_index not in by_index:
            self.pending_index = None
        self.vector_index = k
        return k

    def _take_pending(self, by_index: dict[int, _Seg]) -> int:
        """The chosen branch becomes the Vector, pointing away from the intersection."""
        k, self.pending_index, self.next_turn_deg = self.pending_index, None, None
        s = by_index[k]
        at = self._pending_at
        if np.hypot(*(s.head - at)) < np.hypot(*(s.tail - at)):
            self._reversed ^= {k}
            by_index[k] = s.reverse()
        return k  # type: ignore[return-value]

    def _choose_branch(self, by_index: dict[int, _Seg], k: int, node: int | None, inter: list[int]) -> None:
        """At the Vector's intersection: the branch nearest the next (or default) turn."""
        if node not in inter:
            return
        target = self.next_turn_deg if self.next_turn_deg is not None else self.default_turn_deg
        lines = self.main.intersections[0].m_intLines
        best = min(((abs((ln.m_angle - target + 180) % 360 - 180), ln.m_index) for ln in lines
                    if ln.m_index != k), default=None)
        if best is not None:
            self.pending_index = best[1]
            it = self.main.intersections[0]
            self._pending_at = np.array([float(it.m_x), float(it.m_y)])

    def reverse_vector(self) -> None:
        """Swap the Vector's head and tail from now on (``reverseVector``)."""
        if self.vector_index is not None:
            self._reversed ^= {self.vector_index}

    def _track(self, segs: list[tuple[np.ndarray, np.ndarray]]) -> list[int]:
        """Tracking indices for this frame's ``(tail, head)`` segments (either way round)."""
        limit = float(self.spec.max_line_compare_px)
        cand = []
        for i, (t, h) in enumerate(segs):
            for k, (pt, ph) in self._prev.items():
                moved = min(max(np.hypot(*(t - pt)), np.hypot(*(h - ph))),
                            max(np.hypot(*(t - ph)), np.hypot(*(h - pt))))
                if moved <= limit:
                    cand.append((float(moved), k, i))
        cand.sort()
        out: list[int | None] = [None] * len(segs)
        used: set[int] = set()
        for _d, k, i in cand:
            if out[i] is None and k not in used:
                out[i] = k
                used.add(k)
        for i in range(len(segs)):
            if out[i] is None:
                for _ in range(256):
                    k, self._counter = self._counter, (self._counter + 1) % 256
                    if k not in used:
                        break
                out[i] = k
                used.add(k)
        self._prev = {k: segs[i] for i, k in enumerate(out)}
        return out  # type: ignore[return-value]
