"""The kit's marks on the lane as one near camera row sees them (a helper of the controllers in
this folder; the kit's numbers: ../../../shared/reference/nxp-cup-rules.md, section 1.2).

The default car's row MARK_ROW looks 0.33 m ahead and spans 0.44 m of ground, so it lies inside
the 0.51 m lane when the car is near the middle: the marks are dark runs across it. The marks
are short along the lane (0.02 m bars): at speed the exposure smears them into a shallow dip,
and the lens darkens the row's ends, so a pixel is dark when it is below MARK_DIP of that
pixel's own recent white (the brightest it read lately, slowly forgotten: a flat field). The finish mark is two bars 0.094 m wide with
a 0.074 m gap (the kit's mark only: a START_FINISH with one bar across the lane is not read);
the speed-limit pieces carry 4 (the zone starts) or 3 (it ends) stripes 0.05 m wide with
0.05 m gaps. The widths in pixels are those of the default camera; pass your own.
"""
from __future__ import annotations

import numpy as np

MARK_ROW = 110
MARK_AHEAD_M = 0.33     # the row's look-ahead of the rear axle (the default car)
MARK_DIP = 0.8
FORGET = 0.99           # per frame: the flat field's memory
PX_PER_M = 128 / 0.437  # the row's scale (its 128 pixels span 0.437 m of ground)
BAR_PX = (0.078 * PX_PER_M, 0.13 * PX_PER_M)    # a finish bar is 0.094 m wide (a stripe 0.05)
STRIPE_PX = (0.03 * PX_PER_M, 0.075 * PX_PER_M)  # a speed-limit stripe is 0.05 m wide


class MarkReader:
    """Reads the marks from the near row, frame after frame (:meth:`read`)."""

    def __init__(self):
        self.white: np.ndarray | None = None

    def dark_runs(self, row: np.ndarray) -> list[tuple[int, int]]:
        """``(first, last)`` columns of the runs below MARK_DIP x the flat field, those touching
        the row's ends left out (an edge line coming in from the side)."""
        r = row.astype(float)
        self.white = r.copy() if self.white is None else np.maximum(self.white * FORGET, r)
        dark = r < MARK_DIP * self.white
        d = np.diff(np.concatenate(([0], dark.astype(np.int8), [0])))
        runs = list(zip(np.flatnonzero(d == 1).tolist(), (np.flatnonzero(d == -1) - 1).tolist()))
        return [(a, b) for a, b in runs if a > 0 and b < len(row) - 1]

    def read(self, row: np.ndarray) -> str | None:
        """``"finish"``, ``"zone_start"`` (4 stripes), ``"zone_end"`` (3 stripes), ``"stripes"`` (2
        or more, part of either) or None."""
        runs = self.dark_runs(row)
        widths = [b - a + 1 for a, b in runs]
        if len(runs) in (1, 2) and all(BAR_PX[0] <= w <= BAR_PX[1] for w in widths):  # one: off-centre
            return "finish"
        if len(runs) in (3, 4) and all(STRIPE_PX[0] <= w <= STRIPE_PX[1] for w in widths):
            return "zone_start" if len(runs) == 4 else "zone_end"
        if len(runs) >= 2 and all(STRIPE_PX[0] <= w <= STRIPE_PX[1] for w in widths):
            return "stripes"  # a speed-limit piece seen in part (the car off the lane's middle)
        return None
