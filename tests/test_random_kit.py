"""trackgen random --kit nxp: random loops of the official kit's pieces (trackgen.random_kit)."""
from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from trackgen.chain import chain
from trackgen.layout import parse_layout
from trackgen.random_kit import CELL_M, RandomKitError, random_kit_layout
from trackgen.validate import errors, validate_track
from vehicle.description import CarDescription

KIT_PIECES = {"START_FINISH", "STRAIGHT", "EXTENDER", "TURN_LEFT", "TURN_RIGHT"}
# sha256 of the layouts of seeds 0..11 with length_m=(8, 25), drawn before --crossings and --mix
# existed for kit tracks: without them the same seeds give the same files
SIMPLE_LOOPS_SHA256 = "11765834bae15dfee7c6da2f14aaafd8d2f4751fcac95d0fa48aa2a34e8a7779"


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10**6), st.sampled_from([(8.0, 40.0), (5.0, 10.0), (20.0, 30.0)]))
def test_kit_tracks_close_validate_and_use_only_kit_pieces(seed, length):
    text = random_kit_layout(seed, length_m=length)
    layout = parse_layout(text, path="r.txt")
    assert layout.kit == "nxp" and {e.kind.name for e in layout.entries} <= KIT_PIECES
    assert all(not e.params for e in layout.entries)  # every piece as the kit makes it
    track = chain(layout)
    assert track.closure_error()[0] < 1e-9 and track.closure_error()[1] < 1e-9
    assert not errors(validate_track(track, CarDescription().min_turn_radius_m))
    assert length[0] - 1e-9 <= track.length_m <= length[1] + 1e-9
    assert sum(e.kind.name == "START_FINISH" for e in layout.entries) == 1


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10**6), st.sampled_from([(1, 1), (2, 2), (0, 3), (1, 2)]),
       st.sampled_from([None, {"chicane": 1.0}, {"straight": 3.0, "chicane": 1.0}]))
def test_kit_tracks_with_crossings_and_waves(seed, crossings, mix):
    length = (8.0, 40.0)
    text = random_kit_layout(seed, length_m=length, crossings=crossings, mix=mix)
    layout = parse_layout(text, path="r.txt")
    kinds = [e.kind.name for e in layout.entries]
    assert set(kinds) <= KIT_PIECES | {"CROSSROADS", "WAVE"} and all(not e.params for e in layout.entries)
    track = chain(layout)
    assert track.closure_error()[0] < 1e-9 and track.closure_error()[1] < 1e-9
    assert not errors(validate_track(track, CarDescription().min_turn_radius_m))
    assert length[0] - 1e-9 <= track.length_m <= length[1] + 1e-9
    # each intersection is one physical piece crossed twice, its second pass on its side road,
    # between two EXTENDERs (the kit's stubs) both times
    revisits = [p for p in track.passes if p.revisit]
    assert crossings[0] <= len(revisits) <= crossings[1]
    assert len(revisits) == kinds.count("CROSSROADS") - len(revisits)
    assert len({p.revisit_of for p in revisits}) == len(revisits)
    for i, kind in enumerate(kinds):
        if kind in ("CROSSROADS", "WAVE"):
            assert kinds[i - 1] == kinds[(i + 1) % len(kinds)] == "EXTENDER"
    if not mix:
        assert "WAVE" not in kinds


def test_waves_follow_the_mix():
    def waves(mix):
        return sum(random_kit_layout(s, length_m=(20.0, 30.0), mix=mix).count("\nWAVE") for s in range(10))

    assert waves(None) == 0 < waves({"straight": 3, "chicane": 1}) < waves({"chicane": 1})


def test_without_the_new_options_seeds_draw_the_same_loops():
    digest = hashlib.sha256()
    for seed in range(12):
        digest.update(random_kit_layout(seed, length_m=(8.0, 25.0)).encode())
    assert digest.hexdigest() == SIMPLE_LOOPS_SHA256


def test_same_seed_same_text_and_the_line_follower_laps_one(tmp_path):
    from simrunner.run.runner import drive

    assert random_kit_layout(11) == random_kit_layout(11) != random_kit_layout(12)
    path = tmp_path / "k.txt"
    path.write_text(random_kit_layout(2, length_m=(8.0, 12.0)))
    r = drive(Path(__file__).resolve().parents[1] / "examples" / "line_follower.py", track=path)
    assert r.outcome == "finished", r.message


def test_the_line_follower_laps_a_track_with_two_crossings_and_a_wave(tmp_path):
    """The judge counts the lap only when every pass is driven in order, straight on at both
    intersections (a follower turning off there ends the run off_course)."""
    from simrunner.run.runner import drive

    text = random_kit_layout(4, length_m=(12.0, 30.0), crossings=(1, 2), mix={"straight": 3, "chicane": 1})
    assert text.count("# second pass") == 2 and text.count("\nWAVE") >= 1
    path = tmp_path / "k.txt"
    path.write_text(text)
    r = drive(Path(__file__).resolve().parents[1] / "examples" / "line_follower.py", track=path)
    assert r.outcome == "finished", r.message
    assert r.lap_distances_m[0] > 0.9 * chain(parse_layout(text, path="k.txt")).length_m


def test_bad_options():
    with pytest.raises(RandomKitError, match="the shortest kit loop"):
        random_kit_layout(0, length_m=(1.0, 2.0))
    with pytest.raises(RandomKitError, match="the shortest kit loop with 2 crossing"):
        random_kit_layout(0, length_m=(8.0, 19.0), crossings=2)
    with pytest.raises(RandomKitError, match=r"crossings = 9: expected 0 <= min <= max <= 8"):
        random_kit_layout(0, crossings=9)
    with pytest.raises(RandomKitError, match="'turn' is not for kit tracks"):
        random_kit_layout(0, mix={"turn": 1})
    with pytest.raises(RandomKitError, match="unknown kind 'wave'"):
        random_kit_layout(0, mix={"wave": 1})
    with pytest.raises(RandomKitError, match="expected weights >= 0"):
        random_kit_layout(0, mix={"straight": 0})
    with pytest.raises(RandomKitError, match="seed"):
        random_kit_layout(-1)
    assert CELL_M == pytest.approx(0.72 + 0.17)


def test_cli(tmp_path):
    from trackgen.cli import main as cli

    out = tmp_path / "k.txt"
    res = CliRunner().invoke(cli, ["random", "--kit", "nxp", "--seed", "4", "--length", "8:14", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "@kit = nxp" in out.read_text()
    res = CliRunner().invoke(cli, ["random", "--kit", "nxp", "--seed", "4", "--length", "14:30", "--crossings", "1",
                                   "--mix", "straight=1,chicane=1", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert out.read_text().count("# second pass") == 1
    bad = CliRunner().invoke(cli, ["random", "--kit", "nxp", "--seed", "4", "--walk", "1:2"])
    assert bad.exit_code == 2 and "--walk: not with --kit" in bad.output
    bad = CliRunner().invoke(cli, ["random", "--kit", "nxp", "--seed", "4", "--mix", "turn=1"])
    assert bad.exit_code == 2 and "'turn' is not for kit tracks" in bad.output
