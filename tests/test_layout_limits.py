"""Layout hardening (issue 13 items 11, 12): every number has a range, every check and its
output are bounded, nothing but a ``file:line:`` LayoutError comes out of any layout text."""
from __future__ import annotations

import math
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from pieces.geometry import MAX_ARC_SEGMENTS, arc_segments
from pieces.spec import PARAMS, SETTINGS_PARAMS
from trackgen import LayoutError, chain, parse_layout
from trackgen.build import check_layout
from trackgen.chain import MAX_TRACK_VERTICES
from trackgen.layout import MAX_LINE_CHARS, MAX_NUMBER_CHARS
from trackgen.validate import MAX_OVERLAPS, MAX_PROBLEMS, count_errors, errors

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fuzz_layouts import EXAMPLES, mutate, run_case  # noqa: E402


def error_of(text: str) -> LayoutError:
    with pytest.raises(LayoutError) as info:
        chain(parse_layout(text, path="t.txt"))
    return info.value


# -- the fault-injection findings, each as a regression test ------------------------------------
FINDINGS = [
    # item 11: the number regex backtracked (O(n^2)): 20 000 digits took 13 s
    ("STRAIGHT length=" + "1" * 200_000 + "\n", 1, r"line too long \(200016 characters"),
    ("STRAIGHT length=" + "1" * 900 + "x\n", 1, r"STRAIGHT length='?1{30,40}\.\.\.'?: expected a number"),
    ("@scale = " + "1" * 900 + "\nSTRAIGHT\n", 1, r"@scale = '1+\.\.\.': expected a number"),
    ("STRAIGHT" + " " * 5000 + "=1\n", 1, r"line too long"),
    # item 12: tracebacks
    ("STRAIGHT x" + "9" * 4301 + "\n", 1, r"line too long"),  # int() refused > 4300 digits
    ("STRAIGHT x" + "9" * 900 + "\n", 1, r"STRAIGHT x9+\.\.\.: expected a repeat count x1 to x1000"),
    ("@arc_tolerance = 1e-300\nSTRAIGHT\n", 1, r"@arc_tolerance = 1e-300: expected 1e-05 <= arc_tolerance <= 0.05"),
    ("TURN_LEFT radius=1e308\n", 1, r"TURN_LEFT radius=1e308: expected 0.001 <= radius <= 100 \(m\)"),
    ("STRAIGHT length=1e308\n", 1, r"expected 0.001 <= length <= 100 \(m\)"),
    ("STRAIGHT length=1e12\n", 1, r"expected 0.001 <= length <= 100 \(m\)"),
    ("TURN_LEFT radius=1e12 x8\n", 1, r"expected 0.001 <= radius <= 100"),
    ("STRAIGHT length=1e-300\n", 1, r"expected 0.001 <= length"),
    ("TURN_LEFT angle=1e-300\n", 1, r"expected 0.001 <= angle <= 180 \(deg\)"),
    # Unicode look-alikes are not piece, parameter or setting names
    ("ſtraight\n", 1, r"unknown piece 'ſtraight'"),
    ("straıght\n", 1, r"unknown piece 'straıght'"),
    ("START_FINISH MAR\u212a_LENGTH=0.1\n", 1, r"unknown parameter 'MAR\u212a_LENGTH'"),
    ("@ſcale = 2\nSTRAIGHT\n", 1, r"unknown setting @ſcale"),
    ("STRAIGHT length=١\n", 1, r"expected a number"),
    ("STRAIGHT length=1_0\n", 1, r"expected a number"),
]


@pytest.mark.parametrize("text, line, pattern", FINDINGS, ids=[f"f{i}" for i in range(len(FINDINGS))])
def test_fault_injection_findings_are_one_line_errors(text, line, pattern):
    err = error_of(text)
    assert err.line == line
    assert re.search(pattern, err.message), err.message
    assert "\n" not in str(err) and len(str(err)) < 400  # long values are cut short


def test_number_parsing_is_linear_in_the_token():
    """The 200 000-digit number of the report: one error, found without backtracking (the
    regex has no nested quantifiers; the line and number lengths are capped first)."""
    from trackgen.layout import _NUMBER

    digits = "1" * 100_000 + "x"
    assert _NUMBER.match(digits) is None  # returns at once (was O(n^2): minutes)
    with pytest.raises(LayoutError, match="line too long"):
        parse_layout(f"STRAIGHT length={digits}\n", path="t.txt")


def test_every_number_has_a_finite_range():
    for specs in list(PARAMS.values()) + [SETTINGS_PARAMS]:
        for spec in specs.values():
            assert math.isfinite(spec.lo) and math.isfinite(spec.hi), spec
            assert spec.lo > 0 or spec.name in ("mark_gap", "mark_inset", "mark_offset", "transmission"), spec  # sizes: > 0
            assert spec.contains(spec.default)


@settings(max_examples=200, deadline=None)
@given(angle=st.floats(0.0, math.pi), radius=st.floats(1e-6, 1e308), tol=st.floats(1e-300, 1.0))
def test_property_arc_segments_bounded(angle, radius, tol):
    assert 1 <= arc_segments(angle, radius, tol) <= MAX_ARC_SEGMENTS


def test_largest_radius_at_finest_tolerance_and_largest_scale_is_bounded():
    lay = parse_layout("@scale = 100\n@arc_tolerance = 0.00001\nTURN_LEFT radius=100 angle=180 x4\n",
                       path="t.txt")
    track = chain(lay)
    assert all(len(p.piece.centreline) <= MAX_ARC_SEGMENTS + 1 for p in track.passes)


def test_centreline_budget_stops_a_track_too_detailed():
    text = "@arc_tolerance = 0.00001\nSTRAIGHT\nTURN_LEFT radius=100 angle=180 x1000\n"
    err = error_of(text)
    assert "track too detailed" in err.message and str(MAX_TRACK_VERTICES) in err.message
    assert err.line == 3
    # a 10 000-piece layout of default turns stays well inside the budget
    assert len(chain(parse_layout("TURN_LEFT x1000\n" * 10, path="t.txt")).passes) == 10_000


def test_pieces_on_one_circle_give_bounded_problems():
    """`TURN_LEFT angle=90 x1000`: 124 500 problem lines and 23 s before; now the overlap
    search stops after MAX_OVERLAPS and says so, and the unions/meshes are skipped."""
    checked = check_layout(parse_layout("TURN_LEFT angle=90 x1000\n", path="t.txt"))
    overlaps = [p for p in checked.problems if p.check == "overlap"]
    assert len(overlaps) == MAX_OVERLAPS + 1
    assert "overlap search stopped after 20 overlaps" in overlaps[0].message + overlaps[-1].message
    assert checked._geometry is None  # no union of 1000 overlapping pieces


def test_many_problems_are_summarised_with_their_count():
    # 60 turns too tight for the car (radius 0.3 < 0.414 m): each is a problem
    text = "TURN_LEFT radius=0.3 angle=6 x60\n"
    problems = check_layout(parse_layout(text, path="t.txt")).problems
    assert len(problems) == MAX_PROBLEMS + 1
    summary = problems[-1]
    assert summary.check == "summary" and summary.line is None
    assert re.search(r"\.\.\. and \d+ more problem\(s\) not listed \(.*turn_radius \d+", summary.message)
    assert count_errors(problems) == 60 + len([p for p in errors(problems) if p.check == "closure"])


# -- the class of input: properties ----------------------------------------------------------
_VALUES = st.one_of(st.text(max_size=60), st.sampled_from(
    ["0", "1e308", "1e-300", "-0", "1e12", "nan", "1" * 300, "0." + "0" * 50 + "1", "100",
     "180", "1e-5", "0.05", "1e2", "+.5", "5."]))


@settings(max_examples=300, deadline=None)
@given(kind=st.sampled_from(sorted(k.name for k in PARAMS)), data=st.data(), value=_VALUES)
def test_property_any_parameter_value_parses_or_fails_in_one_line(kind, data, value):
    from pieces.spec import PieceType

    key = data.draw(st.sampled_from(sorted(PARAMS[PieceType[kind]])))
    text = f"{kind} {key}={value}\n"
    try:
        lay = parse_layout(text, path="t.txt")
    except LayoutError as exc:
        assert "\n" not in str(exc) and len(str(exc)) < 400 and exc.line >= 1
    else:
        assert PARAMS[PieceType[kind]][key].contains(lay.entries[0].params[key])


@settings(max_examples=200, deadline=None)
@given(key=st.sampled_from(sorted(SETTINGS_PARAMS) + ["scale"]), value=_VALUES)
def test_property_any_setting_value_parses_or_fails_in_one_line(key, value):
    try:
        parse_layout(f"@{key} = {value}\nSTRAIGHT\n", path="t.txt")
    except LayoutError as exc:  # a value with a newline in it is more than one line of the file
        assert "\n" not in str(exc) and len(str(exc)) < 400 and 1 <= exc.line <= 2 + value.count("\n")
        assert exc.line == 1 or "\n" in value


@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
@given(seed=st.integers(0, 2**32 - 1), base=st.sampled_from(sorted(EXAMPLES.glob("*.txt"))))
def test_property_mutated_examples_never_raise_anything_else(seed, base):
    """The fuzzer's mutations (extreme numbers, repeats, settings, look-alikes, damage):
    a TrackError or a checked track -- and a valid one exports and previews."""
    text = mutate(base.read_text(), np.random.default_rng(seed))
    with tempfile.TemporaryDirectory() as tmp:
        run_case(text, Path(tmp))


def test_limits_are_the_documented_ones():
    doc = (Path(__file__).resolve().parents[1] / "docs" / "layout-format.md").read_text()
    assert f"{MAX_LINE_CHARS}" in doc and f"{MAX_NUMBER_CHARS}" in doc
