"""Layout-file parser: grammar, settings, every error with its line, and a property test."""
from __future__ import annotations

import math
import re
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from pieces import PieceType
from trackgen import LayoutError, TrackError, chain, load_layout, parse_layout
from trackgen.layout import MAX_PIECES, MAX_REPEAT

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def parse(text: str):
    return parse_layout(text, path="t.txt")


def error_of(text: str) -> LayoutError:
    with pytest.raises(LayoutError) as info:
        parse(text)
    return info.value


def test_pieces_comments_repeats_and_case():
    lay = parse("# header\n\nstraight   # trailing\nTurn_Left x2\nTURN_LEFT angle=90 radius=0.6\n"
                "STRAIGHT length = 1.25 x3\n")
    kinds = [e.kind for e in lay.entries]
    assert kinds == [PieceType.STRAIGHT] + [PieceType.TURN_LEFT] * 3 + [PieceType.STRAIGHT] * 3
    assert [e.line for e in lay.entries] == [3, 4, 4, 5, 6, 6, 6]
    assert dict(lay.entries[3].params) == {"angle": 90.0, "radius": 0.6}
    assert lay.piece_kwargs(lay.entries[3]) == {"angle_rad": math.pi / 2, "radius_m": 0.6}
    assert dict(lay.entries[4].params) == {"length": 1.25}


def test_settings_and_scale():
    lay = parse("@name = my-track_1\n@lane_width = 0.5\n@edge_width=0.03\n@scale = 2\n"
                "TURN_RIGHT radius=1 angle=30\n")
    assert lay.name == "my-track_1"
    assert lay.scale == 2.0
    assert lay.settings.lane_width_m == pytest.approx(1.0)
    assert lay.settings.edge_width_m == pytest.approx(0.06)
    assert lay.settings.thickness_m == pytest.approx(0.02)          # default, scaled
    assert lay.settings.arc_tolerance_m == pytest.approx(0.001)     # not scaled
    kw = lay.piece_kwargs(lay.entries[0])
    assert kw["radius_m"] == pytest.approx(2.0)
    assert kw["angle_rad"] == pytest.approx(math.radians(30))       # angles not scaled


def test_default_name_is_file_stem(tmp_path):
    f = tmp_path / "my track!.txt"
    f.write_text("STRAIGHT\n")
    assert load_layout(f).name == "my_track_"


@pytest.mark.parametrize("text, line, pattern", [
    ("STRAIGHT\n\nTRUN_LEFT\n", 3,
     r"unknown piece 'TRUN_LEFT' \(expected one of STRAIGHT, .*; did you mean TURN_LEFT\?\)"),
    ("STRAIGHT\nSTRAIGHT\nTURN_LEFT angle=400\n", 3,
     r"TURN_LEFT angle=400: expected 0.001 <= angle <= 180 \(deg\)"),
    ("TURN_LEFT angle=0\n", 1, r"expected 0.001 <= angle <= 180"),
    ("STRAIGHT length=-1\n", 1, r"STRAIGHT length=-1: expected 0.001 <= length <= 100 \(m\)"),
    ("STRAIGHT length=abc\n", 1, r"STRAIGHT length=abc: expected a number \(m\)"),
    ("STRAIGHT length=nan\n", 1, r"expected a number"),
    ("STRAIGHT length=inf\n", 1, r"expected a number"),
    ("TURN_LEFT radus=0.6\n", 1,
     r"TURN_LEFT: unknown parameter 'radus' \(expected radius, angle; did you mean radius\?\)"),
    ("STRAIGHT angle=90\n", 1, r"STRAIGHT: unknown parameter 'angle' \(expected length"),
    ("TURN_LEFT angle=90 angle=45\n", 1, r"angle given twice"),
    ("STRAIGHT 3\n", 1, r"unexpected '3' \(expected key=value parameters or a repeat count"),
    ("STRAIGHT x0\n", 1, rf"STRAIGHT x0: expected a repeat count x1 to x{MAX_REPEAT}"),
    ("STRAIGHT x100000000000000000000\n", 1, r"expected a repeat count x1 to x1000"),
    ("STRAIGHT x2.5\n", 1, r"expected a repeat count"),
    ("STRAIGHT x2 x3\n", 1, r"repeat count given twice"),
    ("\n".join(["STRAIGHT x1000"] * 11) + "\n", 11, rf"too many pieces \(11000 > {MAX_PIECES}"),
    ("", 1, r"empty layout: no pieces"),
    ("# only a comment\n@lane_width = 0.5\n", 1, r"empty layout"),
    ("@lane_widht = 0.5\nSTRAIGHT\n", 1, r"unknown setting @lane_widht .*did you mean lane_width\?"),
    ("@lane_width = 0.5\n@lane_width = 0.6\nSTRAIGHT\n", 2, r"@lane_width set twice \(first on line 1\)"),
    ("@lane_width = -0.5\nSTRAIGHT\n", 1, r"@lane_width = -0.5: expected 0.0001 <= lane_width <= 100 \(m\)"),
    ("@lane_width =\nSTRAIGHT\n", 1, r"@lane_width: missing value"),
    ("@scale = 0\nSTRAIGHT\n", 1, r"@scale = 0: expected 0.01 <= scale <= 100"),
    ("@name = ../evil\nSTRAIGHT\n", 1, r"@name = '../evil': expected 1-64 letters"),
])
def test_errors_name_line_and_expectation(text, line, pattern):
    err = error_of(text)
    assert err.line == line
    assert str(err).startswith(f"t.txt:{line}: ")
    assert re.search(pattern, err.message), err.message
    assert "\n" not in str(err)


def test_binary_garbage_and_non_utf8(tmp_path):
    garbage = tmp_path / "garbage.txt"
    garbage.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(LayoutError, match=r"garbage.txt:1: not a text layout file"):
        load_layout(garbage)
    latin = tmp_path / "latin.txt"
    latin.write_bytes(b"STRAIGHT\nSTRAIGHT\nTURN_LEFT # caf\xe9\n")
    with pytest.raises(LayoutError, match=r"latin.txt:3: not a text layout file \(byte 0xe9"):
        load_layout(latin)
    nul = tmp_path / "nul.txt"
    nul.write_bytes(b"STRAIGHT\x00\n")
    with pytest.raises(LayoutError, match=r"nul.txt:1: not a text layout file \(control byte 0x00"):
        load_layout(nul)


def test_unreadable_files(tmp_path):
    with pytest.raises(LayoutError, match=r"missing.txt: cannot read layout") as info:
        load_layout(tmp_path / "missing.txt")
    assert info.value.line is None
    with pytest.raises(LayoutError, match=r"is a folder"):
        load_layout(tmp_path)


def test_bom_and_crlf_accepted():
    lay = parse_layout("\ufeffSTRAIGHT\r\nTURN_LEFT x2\r\n", path="t.txt")
    assert [e.line for e in lay.entries] == [1, 2, 2]


def test_piece_error_from_constructor_gets_the_line():
    # radius above 0 passes the table, but must exceed half the road width (0.295 m)
    lay = parse("STRAIGHT\nTURN_LEFT radius=0.1\n")
    with pytest.raises(LayoutError, match=r"^t.txt:2: TURN_LEFT radius=0.1: radius=0.1"):
        chain(lay)


def test_examples_parse():
    for f in sorted(EXAMPLES.glob("*.txt")):
        assert load_layout(f).entries, f


# -- property test ---------------------------------------------------------------------------
_TOKENS = st.sampled_from([
    "STRAIGHT", "straight_short", "TURN_LEFT", "TURN_RIGHT", "CROSSROADS", "CHICANE_LEFT",
    "CHICANE_RIGHT", "START_FINISH", "TRUN_LEFT", "angle=90", "angle=400", "angle=-5",
    "radius=0.6", "radius=0.1", "radius=abc", "length=0.3", "length=-1", "length=1e400",
    "offset=0.3", "offset=5", "mark_length=0.2", "x2", "x3", "x0", "x99999", "x", "=", "==1",
    "#", "# comment", "@lane_width = 0.5", "@edge_width=0.01", "@scale = 1.5", "@scale = 0",
    "@bogus = 1", "@name = t", "@name = ..", "@thickness = 0.02", "@arc_tolerance=0.5",
    "\t", "  ", "é", "\u2028",
])
_LINE = st.one_of(
    st.lists(_TOKENS, min_size=0, max_size=5).map(" ".join),
    st.text(max_size=20),
)
_FILE = st.one_of(
    st.lists(_LINE, min_size=0, max_size=10).map(lambda ls: "\n".join(ls).encode("utf-8", "surrogatepass")),
    st.binary(max_size=200),
)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=_FILE)
def test_property_random_layouts_fail_cleanly(data):
    """Either a chained track or a LayoutError/TrackError ``file:line:`` with a line inside
    the file -- never any other exception."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rand.txt"
        path.write_bytes(data)
        n_lines = max(1, data.count(b"\n") + 1)
        try:
            track = chain(load_layout(path))
        except TrackError as exc:
            assert isinstance(exc, LayoutError)
            assert str(exc).startswith(f"{path}:{exc.line}: "), str(exc)
            assert 1 <= exc.line <= n_lines
            assert "\n" not in str(exc)
        else:
            assert len(track.passes) >= 1
