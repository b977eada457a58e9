"""The judge on the course and the rules' race (issue 49): what a counted lap drives, and
what following the course costs.

1. Counted laps against the course: ``examples/line_follower.py`` drives 2 laps on the
   thesis figure 8, the NXP raceways (traced courses, when ``../shared/tracks`` is there)
   and the kit layouts; printed per track: the outcome, the course each counted lap
   followed (the judge's ``lap_courses_m``: the rear-axle midpoint followed along the
   centreline) over the course's length - the target, a counted lap is the course: >= 0.95 -
   and the path it drove over the same length (``lap_distances_m``), which an inside line
   makes shorter on tight turns without skipping anything. On the kit's S oval (2 x 0.72 m
   straights, two half circles of R0.445: 4.236 m) the rear axle of a car with all wheels
   on the road may run 0.21 m inside the centreline (0.275 - 0.077 + 0.0125 m); with the
   default car's smallest turning radius, 0.414 m, the shortest lap it can drive is two
   half circles of 0.414 m joined by 0.36 m straights, 3.33 m (0.785 of the centreline);
   the same half circles concentric with the track, 4.04 m (0.954). The line follower takes
   the half circles at a mean rear-axle radius of about 0.40 m (its steering at the limit).
2. Speed: closed-loop real-time factor (simulated / CPU seconds, the best of ``REPEATS``)
   of a race lap (``--event race``: the lap and the stop after it) on the kit's S oval and
   on its XL set (the track the race is run on) against a practice lap of the figure 8
   measured in the same run (target: no lower), with the line follower and with the race
   example ``examples/events/race.py`` (which brakes after the finish); the per-run cost
   (a drive whose controller returns at once) and the CPU per simulated second, which
   together make the RTF; and the judge's own cost per update with the course followed
   and without (coverage rule).
3. Hills: the same RTF of 2 laps on a track with a HILL against its flat twin (the HILL
   replaced by a straight as long): the kit oval with a hill (``examples/kit_hill.txt``: the
   hill is 40 % of the lap) and the thesis figure 8 with its first two straights made a
   2 m hill (target >= 0.8 of the flat lap); and how high and steep the car went.
"""
from __future__ import annotations

import dataclasses
import re
import tempfile
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
RACE = REPO / "examples" / "events" / "race.py"
REPEATS = 3
LAYOUTS = ("simrunner/data/thesis_figure8.txt", "examples/kit_S.txt", "examples/kit_wave.txt",
           "examples/kit_speed_limit.txt", "examples/kit_M.txt", "examples/kit_crossing45.txt",
           "examples/kit_XL.txt")


def _tracks() -> list[tuple[str, object]]:
    out = [(Path(p).stem, load_track(REPO / p)) for p in LAYOUTS]
    out += [(name, load_track(TRACKS / name)) for name in ("nxp_raceway", "nxp_raceway_octagon")
            if (TRACKS / name).is_dir()]
    return out


def _best_rtf(track, controller=FOLLOWER, **settings) -> float:
    return _best_run(track, controller, **settings)[0]


def _best_run(track, controller=FOLLOWER, **settings) -> tuple[float, float, float]:
    """``(RTF, simulated s, CPU s)`` of the run with the best RTF of ``REPEATS``."""
    best = (0.0, 0.0, 0.0)
    for _ in range(REPEATS):
        c0 = time.process_time()
        r = drive(controller, track=track, **settings)
        cpu = time.process_time() - c0
        best = max(best, (r.sim_time_s / cpu, r.sim_time_s, cpu))
    return best


def _stop_at_once(spinner) -> None:
    """A controller that returns at once: its drive is the per-run cost alone."""


def _setup_ms(track) -> float:
    """CPU milliseconds of a race drive whose controller returns at once (best of 5)."""
    best = float("inf")
    for _ in range(5):
        c0 = time.process_time()
        drive(_stop_at_once, track=track, event="race")
        best = min(best, time.process_time() - c0)
    return best * 1e3


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


def _hill_pairs(tmp: Path) -> list[tuple[str, Path, Path]]:
    """``(name, layout with a hill, its flat twin)``: the kit oval and the figure 8."""
    kit = (REPO / "examples" / "kit_hill.txt").read_text()
    fig8 = (REPO / LAYOUTS[0]).read_text()
    texts = {"kit oval": (kit, re.sub(r"(?m)^HILL.*$", "STRAIGHT length=1.44", kit)),
             "figure 8": (fig8.replace("STRAIGHT\nSTRAIGHT\nTURN_LEFT", "HILL length=2.0\nTURN_LEFT", 1), fig8)}
    out = []
    for name, (hill, flat) in texts.items():
        paths = []
        for tag, text in (("hill", hill), ("flat", flat)):
            path = tmp / f"{name.replace(' ', '_')}_{tag}.txt"
            path.write_text(text)
            paths.append(path)
        out.append((name, *paths))
    return out


def main() -> None:
    print("counted laps (line follower, 2 laps): course followed / course length (target >= 0.95), "
          "driven path / course length")
    for name, track in _tracks():
        r = drive(FOLLOWER, track=track, laps=2)
        length = track.course.length_m
        followed = " ".join(f"{d / length:.3f}" for d in r.lap_courses_m) or "-"
        driven = " ".join(f"{d / length:.3f}" for d in r.lap_distances_m) or "-"
        kind = "traced" if track.course.traced else f"{len(track.course.sections)} passes"
        print(f"  {name:22s} course {length:6.2f} m ({kind}); {r.outcome}: {r.message}; "
              f"followed {followed}; driven {driven}")
    fig8 = load_track(REPO / LAYOUTS[0])
    oval = load_track(REPO / "examples" / "kit_S.txt")
    xl = load_track(REPO / "examples" / "kit_XL.txt")
    practice, p_sim, p_cpu = _best_run(fig8, laps=1)
    print(f"closed-loop RTF (CPU, best of {REPEATS}): figure-8 practice lap {practice:.1f}x "
          f"({p_sim:.2f} s simulated, {p_cpu * 1e3:.0f} ms CPU); per-run cost {_setup_ms(fig8):.1f} ms")
    for name, track in (("kit S", oval), ("kit XL", xl)):
        setup = _setup_ms(track)
        for label, controller in (("line follower", FOLLOWER), ("race.py", RACE)):
            race, sim, cpu = _best_run(track, controller, event="race")
            print(f"  {name} race lap, {label}: {race:.1f}x ({race / practice:.2f} of the figure-8 lap; "
                  f"target >= 1): {sim:.2f} s simulated, {cpu * 1e3:.0f} ms CPU = per-run cost {setup:.1f} ms "
                  f"+ {(cpu * 1e3 - setup) / sim:.1f} ms per simulated s")
    print(f"  kit S practice lap (line follower): {_best_rtf(oval, laps=1):.1f}x")
    for name, track in (("figure 8", fig8), ("kit S", oval)):
        print(f"judge update on {name}: {_judge_cost_us(track, True):.1f} us following the course, "
              f"{_judge_cost_us(track, False):.1f} us with the coverage rule")
    with tempfile.TemporaryDirectory() as tmp:
        for name, hill_path, flat_path in _hill_pairs(Path(tmp)):
            hill, flat = load_track(hill_path), load_track(flat_path)
            r = drive(FOLLOWER, track=hill, laps=2)
            rtf_hill, rtf_flat = _best_rtf(hill, laps=2), _best_rtf(flat, laps=2)
            print(f"hill on the {name}: {r.outcome}, up to {r.log.z_m.max() * 100:.1f} cm, pitch "
                  f"{abs(r.log.pitch_rad).max() * 57.2958:.1f} deg; RTF {rtf_hill:.1f}x vs flat {rtf_flat:.1f}x "
                  f"({rtf_hill / rtf_flat:.2f}; target >= 0.8)")


if __name__ == "__main__":
    main()
