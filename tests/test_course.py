"""The course a lap follows (simrunner.track.course, .trace), the judge on it, and the rules'
race (simrunner.run.rules, --event race)."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.run.rules import STOP_PENALTY_S, StopCheck
from simrunner.run.runner import drive
from simrunner.run.settings import RunSettings, SettingsError
from simrunner.track import load_track
from simrunner.track.course import traced_course
from simrunner.track.load import road_extents_m

REPO = Path(__file__).resolve().parents[1]
TRACKS = REPO.parent / "shared" / "tracks"
FOLLOWER = REPO / "examples" / "line_follower.py"


def _distance_to_polyline(points: np.ndarray, loop: np.ndarray) -> np.ndarray:
    a = loop
    b = np.roll(loop, -1, axis=0)
    d = b - a
    t = np.clip(np.einsum("pkj,kj->pk", points[:, None, :] - a[None], d) / np.einsum("kj,kj->k", d, d), 0, 1)
    near = a[None] + t[..., None] * d[None]
    return np.hypot(*(near - points[:, None, :]).transpose(2, 0, 1)).min(axis=1)


@pytest.mark.parametrize("layout", ["simrunner/data/thesis_figure8.txt", "examples/kit_M.txt",
                                    "examples/kit_wave.txt"])
def test_traced_course_follows_the_layout_centreline(layout):
    """Traced on a layout's raster (as for a world without a centreline), the course lies on
    the layout's own centreline, through its crossings straight on, and is as long."""
    track = load_track(REPO / layout)
    traced = traced_course(track.raster, track.gate, sum(road_extents_m(track.raster, track.gate)),
                           track.lap_length_m)
    assert traced is not None and traced.traced and not traced.sections
    true = np.asarray(track.centreline)
    off = _distance_to_polyline(traced.centreline, true)
    assert np.percentile(off, 95) < 0.02 and off.max() < 0.06
    assert traced.length_m == pytest.approx(track.course.length_m, rel=0.02)
    # and the other way round: every part of the course was traced (both passes of a crossing)
    assert _distance_to_polyline(true[::3], traced.centreline).max() < 0.06


@pytest.mark.parametrize("name", ["nxp_raceway", "nxp_raceway_octagon"])
def test_gazebo_worlds_get_a_traced_course(name):
    if not (TRACKS / name).is_dir():
        pytest.skip(f"no {TRACKS / name}")
    track = load_track(TRACKS / name)
    course = track.course
    assert course is not None and course.traced
    assert track.raster.on_road(course.centreline).all()
    assert track.lap_length_m == course.length_m
    # the area estimate undercounts a crossing (driven twice); the trace does not
    area = np.count_nonzero(track.raster.road_mask) * track.raster.m_per_px ** 2
    assert 0.97 < course.length_m / (area / sum(road_extents_m(track.raster, track.start))) < 1.1
    assert course.describe(course.s_finish_m + 2.5) == f"2.50 m after the finish line (of {course.length_m:.2f} m)"


def test_course_sections_name_pieces_and_lines():
    track = load_track(REPO / "simrunner" / "data" / "thesis_figure8.txt")
    course = track.course
    secs = course.sections
    assert [s.index for s in secs] == list(range(len(secs)))
    assert secs[0].s_start_m == 0.0 and secs[-1].s_end_m == pytest.approx(course.length_m, abs=1e-9)
    assert all(a.s_end_m == b.s_start_m for a, b in zip(secs, secs[1:]))
    crossings = [s for s in secs if s.kind == "CROSSROADS"]
    assert [(s.index, s.line) for s in crossings] == [(0, 7), (13, 20)]  # each pass its own line
    mid = 0.5 * (secs[3].s_start_m + secs[3].s_end_m)
    assert course.describe(mid) == secs[3].describe() == f"{secs[3].kind} (piece 3, line {secs[3].line})"


def test_a_built_folder_carries_the_course(tmp_path):
    from trackgen.build import build

    layout = REPO / "examples" / "kit_M.txt"
    build(layout, tmp_path / "out")
    doc = json.loads((tmp_path / "out" / "track.json").read_text())
    assert [c["kind"] for c in doc["course"]][:3] == [p["kind"] for p in doc["pieces"]][:3]
    built, direct = load_track(tmp_path / "out"), load_track(layout)
    assert built.course.sections == direct.course.sections
    assert np.array_equal(built.course.centreline, direct.course.centreline)


def test_counted_laps_drive_the_whole_course():
    """The line follower's counted laps follow the whole course (the judge's ``lap_courses_m``,
    within 1 %) and drive about the centreline's length: >= 0.95 of it on the figure 8 (a
    crossing each lap); on the kit's oval, whose 0.445 m turns it takes on their inside,
    >= 0.9. It turns at the kit figure 8's crossing: off the course, named."""
    for layout, share in (("simrunner/data/thesis_figure8.txt", 0.95), ("examples/kit_S.txt", 0.9)):
        track = load_track(REPO / layout)
        r = drive(FOLLOWER, track=track, laps=2)
        assert r.outcome == "finished", (layout, r.message)
        assert len(r.lap_distances_m) == 2
        assert all(d >= share * track.course.length_m for d in r.lap_distances_m), r.lap_distances_m
        assert r.lap_courses_m == pytest.approx([track.course.length_m] * 2, rel=0.01)
    r = drive(FOLLOWER, track=REPO / "examples" / "kit_M.txt", laps=1)
    assert r.outcome == "off_course" and r.message.startswith("turned at CROSSROADS (piece 11, line 17)")


def test_stop_check_after_the_finish():
    check = StopCheck(10.0, 50.0)
    assert check.update(10.1, 50.5, 1.0, 0) is None
    text, penalty = check.update(10.5, 51.2, 0.01, 0)
    assert text == "stopped 1.20 m after the finish line" and penalty is None
    text, penalty = StopCheck(10.0, 50.0).update(11.0, 52.01, 0.5, 0)
    assert penalty.seconds == STOP_PENALTY_S and "did not stop within 2 m" in text
    text, penalty = StopCheck(10.0, 50.0).update(10.2, 50.3, 0.5, 1)
    assert penalty.seconds == STOP_PENALTY_S and text == "left the track after the finish line"
    text, penalty = StopCheck(10.0, 50.0).update(20.0, 51.0, 0.05, 0)
    assert penalty is not None and text.startswith("still rolling 10.0 s")


def _stopping_follower(stop_after_m: float):
    """The line follower (examples/line_follower.py's rule) that brakes to a stop once it has
    driven ``stop_after_m`` (its own odometry: speed x time)."""
    import runpy

    follower = runpy.run_path(str(FOLLOWER))

    def main(s):
        travelled, t_prev = 0.0, 0.0

        class Braking:  # the follower's Spinner, with the speed replaced once past the mark
            def __getattr__(self, name):
                return getattr(s, name)

            def set_speed_and_servo(self, speed, angle):
                nonlocal travelled, t_prev
                t = s.get_time()
                travelled += s.get_speed() * (t - t_prev)
                t_prev = t
                s.set_speed_and_servo(0.0 if travelled > stop_after_m else speed, angle)

        follower["main"](Braking())

    return main


def test_race_event_one_lap_and_the_stop_after_the_finish(tmp_path):
    oval = REPO / "examples" / "kit_S.txt"
    track = load_track(oval)
    # the follower never stops: +1 s once it rolled 2 m past the line
    r = drive(FOLLOWER, track=track, event="race", summary=tmp_path / "s.json")
    assert r.outcome == "finished" and r.passed and r.laps == 1
    assert [p.reason for p in r.penalties] == ["did not stop within 2 m of the finish line"]
    assert r.time_s == pytest.approx(r.lap_times_s[0] + 1.0)
    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["event"] == "race" and doc["passed"] is True and doc["penalty_s"] == 1.0
    assert doc["time_s"] == pytest.approx(r.lap_times_s[0] + 1.0, abs=1e-6) and doc["points"] is None
    # braking 1 m after the line (it starts 0.3 m before it): no penalty, same lap time
    stops = drive(_stopping_follower(track.course.length_m + 0.3 + 1.0), track=track, event="race")
    assert stops.outcome == "finished" and not stops.penalties
    assert "stopped" in stops.message and stops.time_s == pytest.approx(r.lap_times_s[0], abs=0.05)
    with pytest.raises(SettingsError, match="the race event sets its own laps"):
        RunSettings(event="race", laps=2)
    assert RunSettings(event="race").for_track(track).time_limit_s == 120.0


def test_cli_event_race_and_off_track_wheels(tmp_path):
    res = CliRunner().invoke(cli, ["drive", str(FOLLOWER), "--track", str(REPO / "examples" / "kit_S.txt"),
                                   "--event", "race"])
    assert res.exit_code == 0, res.output
    assert "race: passed, time " in res.output and "+1 s: did not stop within 2 m" in res.output
    bad = CliRunner().invoke(cli, ["drive", str(FOLLOWER), "--off-track-wheels", "5"])
    assert bad.exit_code == 2 and "--off-track-wheels" in bad.output


def test_gazebo_world_lap_follows_the_traced_course():
    if not (TRACKS / "nxp_raceway").is_dir():
        pytest.skip("no nxp_raceway")
    track = load_track(TRACKS / "nxp_raceway")
    r = drive(FOLLOWER, track=track, laps=1)
    # a counted lap followed the traced course (the follower cuts the turns: >= 0.9 of its length)
    assert r.outcome == "finished" and r.lap_distances_m[0] >= 0.9 * track.course.length_m
    assert math.isfinite(r.lap_times_s[0])
