"""The judge on the course and the rules' race (issue 49): what a counted lap drives, and
what following the course costs.

1. Counted laps against the course: ``examples/line_follower.py`` drives 2 laps on the
   thesis figure 8, the NXP raceways (traced courses, when ``../shared/tracks`` is there)
   and the kit layouts; printed per track: the outcome, each counted lap's driven path
   (rear-axle midpoint) over the course's centreline length (target >= 0.95 where the car
   keeps to the middle; a follower that takes tight turns on their inside drives less).
2. Speed: closed-loop real-time factor (simulated / CPU seconds, the best of ``REPEATS``)
   of a race lap on the kit's S oval (``--event race``: the lap and the stop after it)
   against a practice lap of the figure 8 measured in the same run (target: no lower), and
   the judge's own cost per update with the course followed and without (coverage rule).
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from pieces.pose import Pose2
from simrunner.run.judge import Judge
from simrunner.run.runner import drive
from simrunner.run.start import wheel_points
from simrunner.track import load_track
from simrunner.track.progress import CentrelineProgress
from vehicle.description import CarDescription

REPO = Path(__file__).resolve().parents[1]
TRACKS = REPO.parent / "shared" / "tracks"
FOLLOWER = REPO / "examples" / "line_follower.py"
REPEATS = 3
LAYOUTS = ("simrunner/data/thesis_figure8.txt", "examples/kit_S.txt", "examples/kit_wave.txt",
           "examples/kit_speed_limit.txt", "examples/kit_M.txt", "examples/kit_crossing45.txt")


def _tracks() -> list[tuple[str, object]]:
    out = [(Path(p).stem, load_track(REPO / p)) for p in LAYOUTS]
    out += [(name, load_track(TRACKS / name)) for name in ("nxp_raceway", "nxp_raceway_octagon")
            if (TRACKS / name).is_dir()]
    return out


def _best_rtf(track, **settings) -> float:
    best = 0.0
    for _ in range(REPEATS):
        c0 = time.process_time()
        r = drive(FOLLOWER, track=track, **settings)
        best = max(best, r.sim_time_s / (time.process_time() - c0))
    return best


def _judge_cost_us(track, course: bool) -> float:
    """Mean CPU microseconds of one ``Judge.update`` along the track's centreline."""
    car = CarDescription()
    t = track if course else dataclasses.replace(track, course=None)
    judge = Judge(t, laps=100)
    along = CentrelineProgress(track.course.centreline)
    poses = [Pose2(*along.point_at(k * 0.02)) for k in range(2000)]
    wheels = [wheel_points(car, q) for q in poses]
    c0 = time.process_time()
    for k, (q, w) in enumerate(zip(poses, wheels)):
        judge.update(k * 0.01, q, w)
    return (time.process_time() - c0) / len(poses) * 1e6


def main() -> None:
    print("counted laps (line follower, 2 laps): driven path / course length")
    for name, track in _tracks():
        r = drive(FOLLOWER, track=track, laps=2)
        shares = " ".join(f"{d / track.course.length_m:.3f}" for d in r.lap_distances_m) or "-"
        kind = "traced" if track.course.traced else f"{len(track.course.sections)} passes"
        print(f"  {name:22s} course {track.course.length_m:6.2f} m ({kind}); {r.outcome}: "
              f"{r.message}; laps {shares}")
    fig8 = load_track(REPO / LAYOUTS[0])
    oval = load_track(REPO / "examples" / "kit_S.txt")
    practice = _best_rtf(fig8, laps=1)
    race = _best_rtf(oval, event="race")
    oval_practice = _best_rtf(oval, laps=1)
    print(f"closed-loop RTF (CPU, best of {REPEATS}): figure-8 practice lap {practice:.1f}x, "
          f"kit S race lap {race:.1f}x ({race / practice:.2f} of it; target >= 1), "
          f"kit S practice lap {oval_practice:.1f}x")
    for name, track in (("figure 8", fig8), ("kit S", oval)):
        print(f"judge update on {name}: {_judge_cost_us(track, True):.1f} us following the course, "
              f"{_judge_cost_us(track, False):.1f} us with the coverage rule")


if __name__ == "__main__":
    main()
