"""trackgen random --kit nxp: random loops of the official kit's pieces (trackgen.random_kit)."""
from __future__ import annotations

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


def test_same_seed_same_text_and_the_line_follower_laps_one(tmp_path):
    from simrunner.run.runner import drive

    assert random_kit_layout(11) == random_kit_layout(11) != random_kit_layout(12)
    path = tmp_path / "k.txt"
    path.write_text(random_kit_layout(2, length_m=(8.0, 12.0)))
    r = drive(Path(__file__).resolve().parents[1] / "examples" / "line_follower.py", track=path)
    assert r.outcome == "finished", r.message


def test_bad_options():
    with pytest.raises(RandomKitError, match="the shortest kit loop"):
        random_kit_layout(0, length_m=(1.0, 2.0))
    with pytest.raises(RandomKitError, match="seed"):
        random_kit_layout(-1)
    assert CELL_M == pytest.approx(0.72 + 0.17)


def test_cli(tmp_path):
    from trackgen.cli import main as cli

    out = tmp_path / "k.txt"
    res = CliRunner().invoke(cli, ["random", "--kit", "nxp", "--seed", "4", "--length", "8:14", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "@kit = nxp" in out.read_text()
    bad = CliRunner().invoke(cli, ["random", "--kit", "nxp", "--seed", "4", "--crossings", "1"])
    assert bad.exit_code == 2 and "--crossings: not with --kit" in bad.output
