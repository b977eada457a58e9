"""trackgen random: seeded layouts that pass every check of ``trackgen validate`` (meshes
included) for the car, the same text for the same seed, options honoured, bad options as
one line, and the CLI (stdout, -o, exit 2)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings, strategies as st

from pieces.pose import Pose2
from trackgen import parse_layout
from trackgen.build import check_layout
from trackgen.cli import main
from trackgen.dubins import csc_paths
from trackgen.random import RandomTrackError, random_layout
from vehicle.description import CarDescription, Steering

SEEDS = list(range(50))


def _check(text: str, car: CarDescription | None = None):
    checked = check_layout(parse_layout(text, path="random.txt"), car)
    assert checked.ok, [str(p) for p in checked.problems]
    return checked


@pytest.mark.parametrize("seed", SEEDS)
def test_fifty_seeds_pass_full_validation(seed):
    text = random_layout(seed)
    checked = _check(text)          # closure, joints, re-entries, overlaps, radius, meshes
    track = checked.track
    assert track.start_finish is not None
    lo, hi = 8.0, 40.0
    assert lo <= track.length_m <= hi
    assert sum(1 for p in track.passes if p.revisit) == text.count("second pass")


def test_same_seed_same_text_and_seeds_differ():
    assert random_layout(7) == random_layout(7)
    assert len({random_layout(s) for s in range(5)}) == 5


@pytest.mark.parametrize("crossings", [0, 1, 2])
def test_crossings_option_is_honoured(crossings):
    for seed in range(3):
        text = random_layout(seed, crossings=crossings)
        track = _check(text).track
        assert len(track.reentries) == crossings
        assert all(r.pass_number == 2 for r in track.reentries)


def test_length_and_mix_options():
    text = random_layout(3, length_m=(12.0, 16.0), mix={"straight": 1, "turn": 0, "chicane": 0},
                         crossings=0)
    track = _check(text).track
    assert 12.0 <= track.length_m <= 16.0
    assert "CHICANE" not in text
    text = random_layout(3, mix={"chicane": 1}, crossings=0, walk_pieces=(3, 3))
    assert text.count("CHICANE") >= 2   # a walk of 3 chicanes (collapsed 'xN' lines count once)


def test_valid_for_a_car_with_a_wide_turning_circle():
    car = CarDescription(steering=Steering(limit_rad=0.3))   # min radius ~0.57 m
    assert 0.55 < car.min_turn_radius_m < 0.6
    for seed in range(3):
        text = random_layout(seed, car=car, radii_m=(0.5, 0.8))
        _check(text, car)
        assert "radius=0.5" not in text


@pytest.mark.parametrize("options, match", [
    ({"crossings": 9}, "crossings"), ({"length_m": (5, 1)}, "length_m"),
    ({"mix": {"spiral": 1}}, "unknown kind 'spiral'"), ({"angles_deg": (0,)}, "angles_deg"),
    ({"radii_m": (0.2,)}, "minimum turning radius"), ({"wobble": 1}, "unknown option 'wobble'"),
])
def test_bad_options_one_clear_error(options, match):
    with pytest.raises(RandomTrackError, match=match):
        random_layout(1, **options)


def test_bad_seed():
    with pytest.raises(RandomTrackError, match="seed"):
        random_layout(-1)


def test_cli_stdout_file_and_bad_input(tmp_path):
    runner = CliRunner()
    res = runner.invoke(main, ["random", "--seed", "4"])
    assert res.exit_code == 0 and res.output == random_layout(4)
    out = tmp_path / "sub" / "r4.txt"
    res = runner.invoke(main, ["random", "--seed", "4", "-o", str(out)])
    assert res.exit_code == 0 and out.read_text() == random_layout(4)
    res = runner.invoke(main, ["validate", str(out)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(main, ["random", "--seed", "4", "--crossings", "1", "--length", "9:35",
                               "--mix", "straight=1,turn=2", "--angles", "45,90", "--radii", "0.8"])
    assert res.exit_code == 0 and res.output.count("second pass") == 1
    res = runner.invoke(main, ["random", "--seed", "4", "--mix", "spiral=1", "-o", str(tmp_path / "x.txt")])
    assert res.exit_code == 2 and "unknown kind 'spiral'" in res.output
    assert not (tmp_path / "x.txt").exists()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(x=st.floats(-5, 5), y=st.floats(-5, 5), yaw=st.floats(-math.pi, math.pi),
       r=st.floats(0.3, 2.0))
def test_dubins_paths_reach_the_goal(x, y, yaw, r):
    start, goal = Pose2(0.0, 0.0, 0.0), Pose2(x, y, yaw)
    paths = csc_paths(start, goal, r)
    assert paths, "LSL and RSR always exist"
    assert [p.length_m for p in paths] == sorted(p.length_m for p in paths)
    for p in paths:
        pose = start
        for turn, arc in ((p.turn1, p.arc1_rad), (0, p.straight_m), (p.turn2, p.arc2_rad)):
            if turn == 0:
                pose = pose @ Pose2(arc, 0.0, 0.0)
            else:
                pose = pose @ Pose2(r * math.sin(arc), turn * r * (1 - math.cos(arc)), turn * arc)
        err_m, err_rad = pose.distance_to(goal)
        # 1e-7: where the two circles touch (an LSR/RSL of straight ~0, p = sqrt(p^2)) the straight
        # carries sqrt(eps) of rounding, ~1e-8 radii
        assert err_m < 1e-7 * r and err_rad < 1e-7
