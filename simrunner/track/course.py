"""The course a lap must follow: the track's centreline in driving order and the pieces along
it (:class:`Course`), which the judge follows (:mod:`simrunner.run.judge`).

- A layout (or its ``trackgen build`` folder) gives the centreline of every pass, crossings
  passed straight on, and where each piece lies along it: a :class:`CourseSection` per pass
  with its kind, its 0-based index in the layout and its layout line.
- A world without a centreline (NXP's Gazebo tracks) gives the road's middle traced on the
  raster from the finish line around the loop (:func:`simrunner.track.trace.trace_loop`,
  straight on at crossings); it has no pieces: places are named by their distance along the
  course from the finish line.
The rules say nothing about crossings; the official crossing piece links opposite arms only,
so the simulator assumes a car goes straight on (rules summary, section 3, "Intersections").
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pieces.pose import Pose2


@dataclass(frozen=True)
class CourseSection:
    """One pass of the layout along the course: ``kind`` (``"CROSSROADS"``), ``index``
    (0-based position in the layout), ``line`` (1-based layout line) and where it lies along
    the centreline, ``s_start_m`` to ``s_end_m``."""

    kind: str
    index: int
    line: int
    s_start_m: float
    s_end_m: float

    def describe(self) -> str:
        return f"{self.kind} (piece {self.index}, line {self.line})"


@dataclass(frozen=True, eq=False)
class Course:
    """``centreline`` ``(N, 2)`` world metres, a closed loop in driving order (the last point
    joins the first), arc length 0 at its first point; ``sections`` the pieces along it
    (empty for a traced course); ``traced``: the centreline was traced on the raster;
    ``s_finish_m``: arc length of the finish line (traced courses start there)."""

    centreline: np.ndarray
    sections: tuple[CourseSection, ...] = ()
    traced: bool = False
    s_finish_m: float = 0.0

    @property
    def length_m(self) -> float:
        pts = np.vstack([self.centreline, self.centreline[:1]])
        return float(np.hypot(*np.diff(pts, axis=0).T).sum())

    def section_at(self, s_m: float) -> CourseSection | None:
        """The piece at arc length ``s_m`` (modulo the loop), None on a traced course."""
        if not self.sections:
            return None
        s = float(s_m) % self.length_m
        for sec in self.sections:
            if s < sec.s_end_m:
                return sec
        return self.sections[-1]

    def describe(self, s_m: float) -> str:
        """Where ``s_m`` is, in a user's words: the piece and its layout line, or the
        distance along a traced course from the finish line."""
        sec = self.section_at(s_m)
        if sec is not None:
            return sec.describe()
        length = self.length_m
        return f"{(float(s_m) - self.s_finish_m) % length:.2f} m after the finish line (of {length:.2f} m)"


def course_from_sections(centreline: np.ndarray, sections, gate: Pose2) -> Course:
    """A layout's course: its ``centreline``, ``(index, kind, line, s_start_m, s_end_m)``
    per pass (``trackgen.Track.course_sections`` or a track.json's ``course``; a track.json
    written before it has none) and the finish line ``gate``."""
    from simrunner.track.progress import CentrelineProgress

    pts = np.asarray(centreline, dtype=float)
    follow = CentrelineProgress(pts)
    follow.reset(gate.x_m, gate.y_m)
    return Course(pts, tuple(CourseSection(kind, index, line, a, b) for index, kind, line, a, b in sections),
                  s_finish_m=follow.s_m)


def traced_course(raster, gate: Pose2, road_width_m: float, lap_length_hint_m: float) -> Course | None:
    """The course of a world without a centreline: the road's middle traced from ``gate``
    (the finish line, heading the driving direction) around the loop; None when the road
    cannot be followed around a loop (the judge then falls back to its coverage rule)."""
    from simrunner.track.trace import trace_loop

    if not road_width_m > 0.0 or not math.isfinite(lap_length_hint_m):
        return None
    loop = trace_loop(raster, gate, road_width_m, max_length_m=3.0 * lap_length_hint_m + 10.0)
    if loop is None or len(loop) < 3:
        return None
    return Course(loop, traced=True)
