"""``@scale`` scales every length (issue 13 item 1) and closure errors name their cause
(item 2)."""
from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from trackgen import LayoutError, chain, load_layout, parse_layout
from trackgen.build import check_layout
from trackgen.validate import validate_track

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def scaled(text: str, scale: float) -> str:
    return f"@scale = {scale!r}\n" + text


def closure_checks(track) -> list[str]:
    """The closure-related problems (the car's turning radius does not scale, on purpose)."""
    return [p.check for p in validate_track(track, 0.0) if p.check in ("closure", "reentry")]


# -- item 1: the README's advice --------------------------------------------------------------
@pytest.mark.parametrize("name, lap_m", [("thesis_figure8", 14.7398), ("oval_start", 11.0795)])
def test_readme_scale_1_3_advice_works_on_the_examples(name, lap_m):
    text = (EXAMPLES / f"{name}.txt").read_text()
    base = check_layout(parse_layout(text, path=f"{name}.txt"))
    big = check_layout(parse_layout(scaled(text, 1.3), path=f"{name}.txt"))
    assert big.ok, [str(p) for p in big.problems]
    assert base.track.length_m == pytest.approx(lap_m, abs=1e-3)
    assert big.track.length_m == pytest.approx(1.3 * base.track.length_m, rel=1e-12)
    s = big.track.layout.settings
    assert s.lane_width_m == pytest.approx(0.715) and s.edge_width_m == pytest.approx(0.026)
    assert s.thickness_m == pytest.approx(0.013) and s.arc_tolerance_m == 0.001
    for a, b in zip(base.track.passes, big.track.passes):
        assert b.exit_world.x_m == pytest.approx(1.3 * a.exit_world.x_m, abs=1e-12)
        assert b.exit_world.y_m == pytest.approx(1.3 * a.exit_world.y_m, abs=1e-12)
        assert b.exit_world.yaw_rad == pytest.approx(a.exit_world.yaw_rad, abs=1e-12)


def test_scale_1_keeps_the_geometry_bit_identical():
    text = (EXAMPLES / "oval_start.txt").read_text()
    a, b = chain(parse_layout(text, path="x")), chain(parse_layout(scaled(text, 1.0), path="x"))
    assert (a.centreline() == b.centreline()).all()
    assert [p.piece for p in a.passes] == [p.piece for p in b.passes]


def test_constructor_errors_name_the_layout_parameter_and_the_scale():
    err = pytest.raises(LayoutError, chain, parse_layout(
        "@lane_width = 0.7\nCROSSROADS length=0.6\n", path="t.txt")).value
    assert err.line == 2 and "length_m" not in err.message
    assert re.search(r"CROSSROADS length=0.6: length=0.6 m: expected \[0.74, inf\) m", err.message)
    err = pytest.raises(LayoutError, chain, parse_layout(
        "@scale = 2\nTURN_LEFT radius=0.1\n", path="t.txt")).value
    assert "radius_m" not in err.message and "radius=0.2 m" in err.message
    assert "(lengths after @scale = 2)" in err.message


# -- item 1: property over scales and layouts ---------------------------------------------------
def _rectangle(a: float, b: float, b2: float, r: float, explicit: tuple[bool, ...]) -> str:
    """A rectangle of 90-degree turns; closes iff b2 == b. Lengths equal to the defaults are
    written or left out as ``explicit`` says (mixing explicit and default lengths)."""
    def straight(length, show):
        return "STRAIGHT" if (length == 1.0 and not show) else f"STRAIGHT length={length!r}"

    def turn(show):
        return "TURN_LEFT angle=90" if (r == 0.8 and not show) else f"TURN_LEFT angle=90 radius={r!r}"
    sides = [straight(a, explicit[0]), turn(explicit[1]), straight(b, explicit[2]),
             turn(explicit[3]), straight(a, explicit[4]), turn(explicit[5]),
             straight(b2, explicit[6]), turn(explicit[7])]
    return "\n".join(sides) + "\n"


_LENGTH = st.sampled_from([1.0, 0.5, 0.3, 2.25, 1.7])
_LAYOUTS = st.one_of(
    st.sampled_from([p.read_text() for p in sorted(EXAMPLES.glob("*.txt"))]),
    st.builds(_rectangle, _LENGTH, _LENGTH, _LENGTH, st.sampled_from([0.8, 0.6, 1.25]),
              st.tuples(*[st.booleans()] * 8)),
)
_SCALES = st.one_of(st.sampled_from([0.01, 0.37, 1.3, 2.0, 100.0]),
                    st.floats(0.01, 100.0, allow_nan=False))


@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
@given(text=_LAYOUTS, scale=_SCALES)
def test_property_scaled_layout_is_the_unscaled_one_scaled(text, scale):
    base = chain(parse_layout(text, path="t.txt"))
    big = chain(parse_layout(scaled(text, scale), path="t.txt"))
    assert big.length_m == pytest.approx(scale * base.length_m, rel=1e-9)
    for a, b in zip(base.passes, big.passes):
        assert b.piece.length_m == pytest.approx(scale * a.piece.length_m, rel=1e-9)
        assert b.exit_world.x_m == pytest.approx(scale * a.exit_world.x_m, rel=1e-9, abs=1e-9 * scale)
        assert b.exit_world.y_m == pytest.approx(scale * a.exit_world.y_m, rel=1e-9, abs=1e-9 * scale)
        assert math.remainder(b.exit_world.yaw_rad - a.exit_world.yaw_rad, math.tau) == pytest.approx(0, abs=1e-9)
    assert closure_checks(big) == closure_checks(base)


def test_mixed_explicit_and_default_lengths_close_at_any_scale():
    text = _rectangle(1.0, 0.5, 0.5, 0.8, (True, False, False, True, False, True, True, False))
    for scale in (1.0, 1.3, 0.5, 10.0):
        assert closure_checks(chain(parse_layout(scaled(text, scale), path="t"))) == []


# -- item 2: closure errors point at the cause ----------------------------------------------------
CLOSURE_CASES = [
    # an 85-degree turn among 90s: named at its own line
    ("STRAIGHT\nTURN_LEFT angle=90\nSTRAIGHT\nTURN_LEFT angle=90\nSTRAIGHT\nTURN_LEFT angle=85\n"
     "STRAIGHT\nTURN_LEFT angle=90\n", 6,
     r"turns sum to 355 deg; 360 needed \(5 deg short\): the turn on line 6 \(TURN_LEFT angle=85\) "
     r"is the odd one out; angle=90 would close the heading"),
    # one turn too many
    ("STRAIGHT\nTURN_RIGHT angle=90 x5\nSTRAIGHT\n", 3,
     r"turns sum to -450 deg; -360 needed \(90 deg too many\)"),
    # the thesis figure 8 with one right turn missing: 0 needed
    ((EXAMPLES / "thesis_figure8.txt").read_text().replace("TURN_RIGHT\nSTRAIGHT_SHORT",
                                                           "STRAIGHT_SHORT"), None,
     r"turns sum to 45 deg; 0 needed \(45 deg too many\)"),
    # a straight missing on the way back (examples/broken.txt)
    ((EXAMPLES / "broken.txt").read_text(), 12,
     r"the headings close \(turns sum to 360 deg\) but the exit is 1.000 m from the start "
     r"\(dx = 1.000 m, dy = 0.000 m\): the pieces heading 180.0 deg \(lines 10, 11\) are 1.000 m "
     r"too short in total, or those heading 0.0 deg \(lines 7, 8\) 1.000 m too long"),
    # one straight too long: the only run heading that way is named at its line
    ("STRAIGHT length=1.5\nTURN_LEFT angle=180\nSTRAIGHT\nTURN_LEFT angle=180\n", None,
     r"the pieces heading 180.0 deg \(line 3\) are 0.500 m too short in total, or those "
     r"heading 0.0 deg \(line 1\) 0.500 m too long"),
    # a straight missing on the way out: the gap points along +x, named "0.0 deg" (not "-0.0")
    ("STRAIGHT\nTURN_LEFT angle=180\nSTRAIGHT x2\nTURN_LEFT angle=180\n", None,
     r"\(dx = -1.000 m, dy = 0.000 m\): the pieces heading 0.0 deg \(line 1\) are 1.000 m too "
     r"short in total, or those heading 180.0 deg \(line 3\) 1.000 m too long"),
]


@pytest.mark.parametrize("text, line, pattern", CLOSURE_CASES, ids=[f"c{i}" for i in range(len(CLOSURE_CASES))])
def test_closure_errors_name_the_cause(text, line, pattern):
    problems = [p for p in check_layout(parse_layout(text, path="t.txt")).problems
                if p.check == "closure"]
    assert len(problems) == 1
    (p,) = problems
    assert re.search(pattern, p.message), p.message
    assert p.message.startswith("track does not close: the exit of ")
    if line is not None:
        assert p.line == line


def test_broken_example_is_still_reported_at_its_last_line():
    (p,) = [p for p in check_layout(load_layout(EXAMPLES / "broken.txt")).problems]
    assert str(p).startswith(f"{EXAMPLES / 'broken.txt'}:12: track does not close")


@settings(max_examples=40, deadline=None)
@given(angles=st.lists(st.sampled_from([30.0, 45.0, 60.0, 90.0]), min_size=1, max_size=8),
       change=st.sampled_from([-5.0, 2.5, 7.0]), at=st.integers(0, 7))
def test_property_one_odd_turn_is_found(angles, change, at):
    """A closing ring of left turns (with straights) with one angle changed: the message
    gives the right total and the needed 360."""
    total = sum(angles)
    fill = 360.0 - total % 360.0 if total % 360.0 else 0.0
    parts = math.ceil(fill / 180.0)
    ring = list(angles) + ([fill / parts] * parts if parts else [])
    i = at % len(ring)
    if not 0 < ring[i] + change <= 180:
        return
    ring[i] += change
    text = "".join(f"STRAIGHT length=0.5\nTURN_LEFT angle={a!r}\n" for a in ring)
    (p,) = [p for p in check_layout(parse_layout(text, path="t.txt")).problems if p.check == "closure"]
    assert f"turns sum to {sum(ring):.6g} deg" in p.message
    assert f"{360.0 * round(sum(ring) / 360.0):.6g} needed" in p.message
