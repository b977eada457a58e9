"""Pixy2 barcodes read from the camera's frame, and the edge detector the line tracker shares.

The Pixy2 reads its 4-bit barcodes along the rows of its frame (the firmware's ``detectCode``,
``decodeCode``, ``clusterCodes``, ``voteCodes``: charmedlabs/pixy2,
``src/device/main_m4/src/line.cpp``); we follow its rules on our frame, in our units:

1. **Edges.** Every ``row_step``-th row of the frame is scanned with the line tracker's edge
   detector (:func:`edge_centres`: the step ``p[i + d] - p[i]``, ``d`` = the car file's
   ``pixy2.barcode_edge_distance_px``, against ``pixy2.barcode_edge_threshold``). Falling edges (light
   to dark) and rising edges alternate along a row as bars and gaps do.
2. **A code on a row.** It starts at a falling edge whose bar is followed by a rising edge; the
   quiet zone before it is at least 4 times that first bar wide (or the row starts there).
   The bars and gaps that follow, until one wider than 4 first bars (the quiet zone after),
   are its elements: 7 to 10 of them (the firmware's ``LINE_MMC_MIN_EDGES``,
   ``LINE_MMC_MAX_EDGES``).
3. **Decoding.** The widths, sorted, split into narrow and wide at their widest gap (all narrow
   when that gap is under a quarter of the narrowest width plus half a pixel). From the second
   element on, elements alternate white, black; a wide one, or two narrow ones, make a bit: 1
   when the element completing it is black. Four bits, most significant first, are the code
   (0-15); a row whose widths differ more than 10 times, or whose narrow ones do not pair, has
   none.
4. **Voting.** Codes on rows whose starts lie within ``CLUSTER_PX`` of the last one of a cluster
   (rows count 4 times: ``dx^2 + (4 dy)^2``) join it (at most ``MAX_CODES`` clusters); a
   cluster of 2 or more rows reports the code most of its rows read when at least 2 rows and
   half of them agree.

Each barcode found is a rectangle in frame pixels: the first row's start, the rows' mean
width, from the first to the last row. The line tracker drops line points around it (as the
firmware clears its grid: 10 % of the width to the sides, 25 % of the height up and down, then
4 times that height above), so a barcode's bars are not reported as lines.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CODE_BITS = 4
MIN_ELEMENTS, MAX_ELEMENTS = 7, 10   # line.h: LINE_MMC_MIN_EDGES - 1, LINE_MMC_MAX_EDGES
QUIET_FACTOR = 4.0                   # quiet zones: 4 first-bar widths (line.cpp detectCode)
MAX_RATIO = 10.0                     # widest / narrowest element (line.cpp decodeCode)
CLUSTER_PX = 15.0                    # line.cpp: g_maxCodeDist = 15 * 15 (squared)
ROW_WEIGHT = 4.0                     # line.cpp dist2_4: rows count 4 times
MAX_CODES = 8                        # line.h: LINE_MMC_VOTED_BARCODES
CLEAR_SIDE, CLEAR_BELOW, CLEAR_ABOVE = 0.1, 0.25, 4.0   # line.h LINE_MMC_HBOUNDARY, _VBOUNDARY; clearGrid


def edge_centres(g: np.ndarray, mask: np.ndarray, d: int) -> list[list[float]]:
    """Per scan (row of ``g``): the centres of the runs of ``mask``, weighted by ``|g|``,
    shifted by ``d / 2``."""
    n, m = mask.shape
    pad = np.zeros((n, m + 2), dtype=np.int8)
    pad[:, 1:-1] = mask
    step = np.diff(pad, axis=1)
    rows, starts = np.nonzero(step == 1)   # row-major: runs in order
    _rows, ends = np.nonzero(step == -1)
    w = np.where(mask, np.abs(g), 0.0)
    cw = np.zeros((n, m + 1))
    cxw = np.zeros((n, m + 1))
    np.cumsum(w, axis=1, out=cw[:, 1:])
    np.cumsum(w * np.arange(m), axis=1, out=cxw[:, 1:])
    centres = (cxw[rows, ends] - cxw[rows, starts]) / (cw[rows, ends] - cw[rows, starts]) + d / 2.0
    values, out, i = centres.tolist(), [], 0
    for count in np.bincount(rows, minlength=n).tolist():
        out.append(values[i:i + count])
        i += count
    return out


@dataclass(frozen=True)
class FoundCode:
    """A barcode in the frame: ``code`` and its rectangle (frame pixels: left, top, width, height)."""

    code: int
    x_px: float
    y_px: float
    width_px: float
    height_px: float

    @property
    def centre_px(self) -> tuple[float, float]:
        return self.x_px + self.width_px / 2.0, self.y_px + self.height_px / 2.0


def decode(widths: list[float], ends_falling: list[bool]) -> int | None:
    """The code of a row's elements (widths; whether the edge ending each is a falling one),
    or None (module docstring, 3)."""
    ws = sorted(widths)
    gap, threshold = 0.0, ws[-1] + 1.0
    for a, b in zip(ws, ws[1:]):
        if b - a > gap:
            gap, threshold = b - a, (a + b) / 2.0
    if gap < ws[0] / 4.0 + 0.5:
        threshold = ws[-1] + 1.0
    val, bits, pending, lo, hi = 0, 0, False, np.inf, 0.0
    for i in range(1, len(widths)):
        if bits >= CODE_BITS:
            break
        black = not ends_falling[i]
        if black != (i % 2 == 0):        # odd elements are gaps (white), even ones bars
            return None
        w = widths[i]
        lo, hi = min(lo, w), max(hi, w)
        if w < threshold:
            if pending:
                val, bits, pending = val << 1 | int(black), bits + 1, False
            else:
                pending = True
        elif pending:                     # a wide element after one narrow: no code
            return None
        else:
            val, bits = val << 1 | int(black), bits + 1
    if bits != CODE_BITS or hi / lo > MAX_RATIO:
        return None
    return val


def _row_codes(edges: list[tuple[float, bool]]) -> list[tuple[float, float, int]]:
    """``(start, width, code)`` of every code along one row's sorted edges ``(x, falling)``."""
    out = []
    for j in range(len(edges) - 1):
        if not (edges[j][1] and not edges[j + 1][1]):
            continue
        quiet = QUIET_FACTOR * (edges[j + 1][0] - edges[j][0])
        if j > 0 and edges[j][0] - edges[j - 1][0] < quiet:
            continue
        widths, falling = [], []
        for k in range(j, len(edges) - 1):
            if k - j >= MAX_ELEMENTS:
                widths = []
                break
            w = edges[k + 1][0] - edges[k][0]
            if w > quiet:
                break
            widths.append(w)
            falling.append(edges[k + 1][1])
        if len(widths) < MIN_ELEMENTS:
            continue
        code = decode(widths, falling)
        if code is not None:
            out.append((edges[j][0], float(sum(widths)), code))
    return out


def find_codes(frame: np.ndarray, *, threshold: float, d: int, row_step: int) -> list[FoundCode]:
    """The barcodes of a ``(H, W)`` frame (module docstring), top to bottom as found."""
    rows = np.asarray(frame, dtype=np.float64)[::row_step]
    if rows.shape[1] <= d:
        return []
    g = rows[:, d:] - rows[:, :-d]
    falls = edge_centres(g, g <= -threshold, d)
    rises = edge_centres(g, g >= threshold, d)
    clusters: list[list[tuple[int, float, float, int]]] = []
    for r, (f_row, r_row) in enumerate(zip(falls, rises)):
        if len(f_row) + len(r_row) < MIN_ELEMENTS + 1:
            continue
        edges = sorted([(x, True) for x in f_row] + [(x, False) for x in r_row])
        for x0, width, code in _row_codes(edges):
            for cl in clusters:
                last = cl[-1]
                if (x0 - last[1]) ** 2 + (ROW_WEIGHT * (r - last[0])) ** 2 < CLUSTER_PX ** 2:
                    cl.append((r, x0, width, code))
                    break
            else:
                if len(clusters) < MAX_CODES:
                    clusters.append([(r, x0, width, code)])
    out = []
    for cl in clusters:
        if len(cl) < 2:
            continue
        votes: dict[int, int] = {}
        for *_, code in cl:
            votes[code] = votes.get(code, 0) + 1
        code = max(votes, key=votes.get)  # the first code to reach the most votes
        n = votes[code]
        if n < 2 or 2 * n < len(cl):
            continue
        top, bottom = cl[0][0] * row_step, cl[-1][0] * row_step
        width = float(np.mean([c[2] for c in cl]))
        out.append(FoundCode(code, float(cl[0][1]), float(top), width, float(bottom - top + row_step)))
    return out


def cleared(code: FoundCode) -> tuple[float, float, float, float]:
    """``(x0, x1, y0, y1)`` frame pixels where the line tracker ignores line points (module
    docstring): the rectangle grown by ``CLEAR_SIDE`` of its width to each side and
    ``CLEAR_BELOW`` of its height up and down, then ``CLEAR_ABOVE`` times that height upwards."""
    side, vert = CLEAR_SIDE * code.width_px, CLEAR_BELOW * code.height_px
    top, bottom = code.y_px - vert, code.y_px + code.height_px + vert
    return (code.x_px - side, code.x_px + code.width_px + side, top - CLEAR_ABOVE * (bottom - top), bottom)
