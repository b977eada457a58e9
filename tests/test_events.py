"""The disciplines (simrunner.run.events, --event): their tracks, laps, time limits and
off-track rules, and how each is judged and scored."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from simrunner.cli import main as cli
from simrunner.run.events import EVENTS, event_track
from simrunner.run.runner import drive
from simrunner.run.settings import RunSettings
from simrunner.track import load_track
from simrunner.track.progress import CentrelineProgress

REPO = Path(__file__).resolve().parents[1]
FOLLOWER = REPO / "examples" / "line_follower.py"
KIT_S = REPO / "examples" / "kit_S.txt"


def test_every_event_has_its_rules_and_track():
    for name, rules in EVENTS.items():
        assert rules.rules.startswith("section ")
        path = event_track(name)
        assert path is None or load_track(path).course is not None
        s = RunSettings(event=name)
        assert s.off_track_wheels == rules.off_track_wheels
        assert s.for_track(load_track(KIT_S)).time_limit_s == rules.time_limit_s
    # the other disciplines void an attempt at any part of any wheel off (section 4)
    assert [EVENTS[n].off_track_wheels for n in ("figure8", "speed_limit")] == [1, 1]
    assert RunSettings(event="figure8", off_track_wheels=3).off_track_wheels == 3  # given: wins


def test_figure8_counts_laps_until_the_time_is_up(tmp_path):
    """Laps in 60 s (R20; --time-limit 90 for R19), the run ends at the time, passed when it
    was driven cleanly; the points are by rank among the teams (None)."""
    r = drive(FOLLOWER, track=KIT_S, event="figure8", summary=tmp_path / "s.json")
    assert r.outcome == "finished" and r.sim_time_s == pytest.approx(60.0, abs=0.03)
    assert r.passed and r.laps_completed >= 10 and r.points is None
    assert r.message == f"{r.laps_completed} complete lap(s) in 60 s"
    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["details"] == {"laps": r.laps_completed} and doc["time_s"] is None
    short = drive(FOLLOWER, track=KIT_S, event="figure8", time_limit_s=10.0)
    assert short.laps_completed < r.laps_completed and short.passed
    # the rules' own figure 8: the plain follower turns at its crossing, which voids it
    fails = drive(FOLLOWER, event="figure8")
    assert fails.outcome == "off_course" and not fails.passed


def _zone_driver(track, slow_mps: float | None):
    """A test driver that knows the course: pure pursuit on the centreline, at 1.6 m/s, and at
    ``slow_mps`` between the speed-limit pieces (None: never slows)."""
    follow = CentrelineProgress(track.course.centreline)
    start = next(s for s in track.course.sections if s.kind == "SPEED_LIMIT_START")
    end = next(s for s in track.course.sections if s.kind == "SPEED_LIMIT_END")

    def main(s):
        import math

        x, y, _ = s.get_position()
        follow.reset(x, y)
        yaw = follow.point_at(follow.s_m)[2]  # the heading: from the positions it moves through
        px, py = x, y
        while True:
            x, y, _ = s.get_position()
            if math.hypot(x - px, y - py) > 0.01:
                yaw, px, py = math.atan2(y - py, x - px), x, y
            follow.advance(x, y)
            tx, ty, _ = follow.point_at(follow.s_m + 0.3)
            a = math.atan2(ty - y, tx - x) - yaw
            a = math.atan2(math.sin(a), math.cos(a))
            steer = math.atan2(2 * 0.175 * math.sin(a), 0.3)
            inside = start.s_start_m - 0.3 <= follow.s_m <= end.s_end_m
            s.set_speed_and_servo(slow_mps if (inside and slow_mps) else 1.6, max(-0.4, min(0.4, steer)))
            s.sleep(0.01)

    return main


def test_speed_limit_measures_the_zone():
    track = load_track(event_track("speed_limit"))
    slows = drive(_zone_driver(track, 0.7), track=track, event="speed_limit")
    assert slows.outcome == "finished" and slows.passed and slows.points == 150, slows.message
    d = slows.verdict.details
    assert d["zone_max_mps"] <= 0.6 * d["approach_mps"] and d["after_max_mps"] >= 0.8 * d["approach_mps"]
    assert slows.message.startswith("passed: approach ")
    never = drive(_zone_driver(track, None), track=track, event="speed_limit")
    assert never.outcome == "finished" and not never.passed and never.points == 0
    assert never.message.startswith("failed: ") and "> 0.6 x" in never.message
    # the car starts just past the 3-stripe piece (R20)
    end = next(s for s in track.course.sections if s.kind == "SPEED_LIMIT_END")
    x, y, _ = CentrelineProgress(track.course.centreline).point_at(end.s_end_m + 0.05)
    log = slows.log
    assert (log.x_m[0], log.y_m[0]) == pytest.approx((x, y), abs=1e-3)


def test_cli_event_prints_the_verdict():
    res = CliRunner().invoke(cli, ["drive", str(FOLLOWER), "--event", "figure8", "--track", str(KIT_S),
                                   "--time-limit", "5"])
    assert res.exit_code == 0, res.output
    assert "figure8: passed" in res.output and "laps: " in res.output
    res = CliRunner().invoke(cli, ["drive", str(FOLLOWER), "--event", "speed_limit"])
    assert res.exit_code == 0 and "speed_limit: failed, 0 points" in res.output
    bad = CliRunner().invoke(cli, ["drive", str(FOLLOWER), "--event", "figure8", "--laps", "3"])
    assert bad.exit_code == 2 and "sets its own laps" in bad.output


EVENTS_DIR = REPO / "examples" / "events"


@pytest.mark.parametrize("track", ["kit_S.txt", "kit_wave.txt", "kit_crossing45.txt"])
def test_the_race_example_stops_after_the_kit_finish_mark(track):
    r = drive(EVENTS_DIR / "race.py", track=REPO / "examples" / track, event="race")
    assert r.outcome == "finished" and r.passed and not r.penalties, r.message
    assert "stopped" in r.message


def test_the_race_example_never_stops_early_where_there_is_no_kit_mark():
    """The default pieces' finish bar, the speed-limit stripes: it drives the lap (and takes
    the +1 s) rather than stopping on a mark it cannot read."""
    for track in (REPO / "simrunner" / "data" / "thesis_figure8.txt", REPO / "examples" / "kit_speed_limit.txt"):
        r = drive(EVENTS_DIR / "race.py", track=track, event="race")
        assert r.outcome == "finished" and r.laps_completed == 1, r.message


def test_the_speed_limit_example_passes():
    for seed in range(3):
        r = drive(EVENTS_DIR / "speed_limit.py", event="speed_limit", seed=seed)
        assert r.passed and r.points == 150, r.message


def test_the_figure8_example_goes_straight_on_at_the_crossing_where_the_follower_turns():
    r = drive(EVENTS_DIR / "figure8.py", event="figure8", seed=1)
    assert r.passed and r.outcome == "finished" and r.laps_completed >= 10, r.message
    follower = drive(FOLLOWER, event="figure8")
    assert not follower.passed and follower.outcome == "off_course"
    assert "turned at CROSSROADS" in follower.message


def test_events_refuse_what_they_cannot_judge_in_one_line(tmp_path):
    res = CliRunner().invoke(cli, ["drive", str(FOLLOWER), "--event", "speed_limit", "--track", str(KIT_S)])
    assert res.exit_code == 2 and "needs a layout with SPEED_LIMIT_START" in res.output
    assert "Traceback" not in res.output
    with pytest.raises(Exception, match="keep_driving: not with an event"):
        RunSettings(event="figure8", keep_driving=True)


def test_an_event_reports_its_own_laps_and_time_limit():
    r = drive(FOLLOWER, track=KIT_S, event="figure8", time_limit_s=10.0)
    assert r.message == f"{r.laps_completed} complete lap(s) in 10 s" and r.laps == r.laps_completed


def test_a_layout_box_ends_an_event_too(tmp_path):
    layout = tmp_path / "boxed.txt"
    layout.write_text(KIT_S.read_text() + "@box = 0.36 0.89 0.2 0.2 0.2\n")  # on the far straight
    r = drive(FOLLOWER, track=layout, event="race")
    assert r.outcome == "touched" and not r.passed and r.time_s is None
    assert r.verdict.details["touched"] == "box_1"


def test_a_race_whose_main_returns_after_the_lap_still_counts():
    """main returns once the lap is done (still rolling): the attempt counts, the stop is
    judged on the state it ended in (+1 s while rolling)."""
    def main(s):
        import runpy

        follower = runpy.run_path(str(FOLLOWER))["main"]

        class Until:
            def __getattr__(self, name):
                return getattr(s, name)

            def get_image(self, *a, **k):
                if s.get_time() > 2.95:  # just past the line (lap 2.49 s from ~0.4 s)
                    raise StopIteration
                return s.get_image(*a, **k)

        try:
            follower(Until())
        except StopIteration:
            return

    r = drive(main, track=KIT_S, event="race")
    assert r.outcome == "controller_returned" and r.passed and r.laps_completed == 1
    assert [p.seconds for p in r.penalties] == [1.0] and r.time_s == pytest.approx(r.lap_times_s[0] + 1.0)


def test_batch_event_runs_on_the_events_own_track(tmp_path):
    from simrunner.workflows.batch import run_batch

    res = run_batch(FOLLOWER, out_dir=tmp_path / "b", event="speed_limit", workers=1, plot=False)
    (row,) = res.rows
    assert row["outcome"] == "finished" and "approach" in row["message"]
