"""The official track kit (issue 49, item 1, first slice): ``@kit = nxp`` makes the kit's
pieces the defaults, EXTENDER, and the rules' training sets S and M as example layouts."""
from __future__ import annotations

import math
from pathlib import Path

import pytest
import shapely

from pieces import KITS, PARAMS, PieceType
from trackgen.chain import chain as chain_layout
from trackgen.errors import LayoutError
from trackgen.export import track_geometry
from trackgen.layout import load_layout, parse_layout

REPO = Path(__file__).resolve().parents[1]
OVAL = "START_FINISH\nTURN_LEFT x4\nSTRAIGHT\nTURN_LEFT x4\n"


def test_the_kit_sets_the_pieces_and_the_road_and_given_values_win():
    lay = parse_layout("@kit = NXP\n" + OVAL + "STRAIGHT length=1\nEXTENDER\n")
    assert lay.kit == "nxp"
    assert (lay.settings.lane_width_m, lay.settings.edge_width_m) == (0.51, 0.02)  # 0.55 over the lines
    kw = [lay.piece_kwargs(e) for e in lay.entries]
    assert kw[0] == {"length_m": 0.72, "mark_length_m": 0.02, "mark_gap_m": 0.074, "mark_inset_m": 0.124,
                     "mark_offset_m": 0.2}
    assert kw[1] == {"radius_m": 0.445, "angle_rad": pytest.approx(math.radians(45.0))}
    assert kw[-2] == {"length_m": 1.0} and kw[-1] == {"length_m": 0.17}
    mine = parse_layout("@kit = nxp\n@lane_width = 0.5\nTURN_LEFT radius=0.6 angle=90\n")
    assert mine.settings.lane_width_m == 0.5 and mine.piece_kwargs(mine.entries[0]) == {
        "radius_m": 0.6, "angle_rad": pytest.approx(math.pi / 2)}


def test_without_the_kit_nothing_changes():
    lay = parse_layout(OVAL)
    assert lay.kit is None and lay.piece_kwargs(lay.entries[0]) == {}
    assert PARAMS[PieceType.STRAIGHT]["length"].default == 1.0


def test_an_unknown_kit_is_a_one_line_error():
    with pytest.raises(LayoutError) as err:
        parse_layout("@kit = nxpp\n" + OVAL, path="t.txt")
    assert str(err.value) == "t.txt:1: @kit = 'nxpp': expected one of nxp; did you mean nxp?"


@pytest.mark.parametrize("name, size_m, curves, straights", [("kit_S", (2.16, 1.44), 8, 2),
                                                            ("kit_M", (3.77, 2.33), 12, 4)])
def test_the_training_sets_have_the_rules_envelopes(name, size_m, curves, straights):
    """Rules summary section 1.3: S is an oval 2160 x 1440 mm, M option 1 a figure 8
    3770 x 2330 mm (the kit's intersection counted as CROSSROADS + an EXTENDER each arm)."""
    lay = load_layout(REPO / "examples" / f"{name}.txt")
    track = chain_layout(lay)
    assert track.closure_error()[0] < 1e-9
    x0, y0, x1, y1 = track_geometry(track).road.bounds
    assert (x1 - x0, y1 - y0) == pytest.approx(size_m, abs=1e-6)
    kinds = [e.kind for e in lay.entries]
    assert sum(k in (PieceType.TURN_LEFT, PieceType.TURN_RIGHT) for k in kinds) == curves
    assert sum(k in (PieceType.STRAIGHT, PieceType.START_FINISH) for k in kinds) == straights
    if name == "kit_S":   # "lane-centre lap about 4.24 m (derived: 2 x 720 + 2 pi 445)"
        assert track.length_m == pytest.approx(2 * 0.72 + 2 * math.pi * 0.445, abs=1e-3)


def test_the_xl_layout_uses_the_xl_sets_pieces():
    """Rules summary section 1.3: XL is 14 straights, 32 curves, 1 intersection, 1 chicane and
    the start/finish piece; kit_XL.txt lays out all but one straight (an odd number of 0.72 m
    lengths cannot close with the kit's 0.445 m multiples), closes, validates for the default
    car, and the line follower laps it (through its crossing, straight on)."""
    from simrunner.run.runner import drive
    from trackgen.build import validate_path as validate

    lay = load_layout(REPO / "examples" / "kit_XL.txt")
    kinds = [e.kind for e in lay.entries]
    count = {k: kinds.count(k) for k in set(kinds)}
    assert count[PieceType.TURN_LEFT] + count[PieceType.TURN_RIGHT] == 32
    assert count[PieceType.TURN_LEFT] == count[PieceType.TURN_RIGHT]  # a figure 8: no net turn
    assert (count[PieceType.STRAIGHT], count[PieceType.START_FINISH], count[PieceType.WAVE]) == (13, 1, 1)
    assert count[PieceType.CROSSROADS] == 2  # one intersection, passed twice
    track = chain_layout(lay)
    assert track.closure_error()[0] < 1e-9
    assert validate(REPO / "examples" / "kit_XL.txt") == []
    r = drive(REPO / "examples" / "line_follower.py", track=REPO / "examples" / "kit_XL.txt", laps=1, seed=0)
    assert r.outcome == "finished", r.message


def test_the_kit_cites_its_source():
    assert "nxp-cup-rules.md" in KITS["nxp"].source


def test_the_line_follower_laps_the_kit_oval():
    from simrunner.run.runner import drive

    r = drive(REPO / "examples" / "line_follower.py", track=REPO / "examples" / "kit_S.txt", laps=2, seed=0)
    assert r.outcome == "finished", r.message


def test_the_speed_limit_pieces_carry_the_rules_stripes():
    """Rules summary section 1.2: 4 (start) or 3 (end) stripes of 300 x 50 mm along the lane,
    50 mm gaps, centred across (80 / 130 mm to each edge line), 210 mm from each end."""
    from pieces import speed_limit_end, speed_limit_start
    from pieces.spec import TrackSettings

    kit = TrackSettings(lane_width_m=0.51, edge_width_m=0.02)
    for make, n, to_line in ((speed_limit_start, 4, 0.08), (speed_limit_end, 3, 0.13)):
        p = make(settings=kit)
        parts = list(p.marking.geoms)
        assert len(parts) == n
        for g in parts:
            x0, y0, x1, y1 = g.bounds
            assert (x0, 0.72 - x1, x1 - x0, y1 - y0) == pytest.approx((0.21, 0.21, 0.30, 0.05))
        y_min, y_max = p.marking.bounds[1], p.marking.bounds[3]
        assert (0.255 + y_min, 0.255 - y_max) == pytest.approx((to_line, to_line))
        assert p.lane.intersection(p.marking).area == pytest.approx(0.0, abs=1e-12)
    lay = load_layout(REPO / "examples" / "kit_speed_limit.txt")
    x0, y0, x1, y1 = track_geometry(chain_layout(lay)).road.bounds
    assert (x1 - x0, y1 - y0) == pytest.approx((2.88, 1.44), abs=1e-6)


def test_too_many_stripes_for_the_lane_is_a_one_line_error():
    with pytest.raises(LayoutError) as err:
        chain_layout(parse_layout("@kit = nxp\nSPEED_LIMIT_START stripe_width=0.2\n", path="t.txt"))
    assert "t.txt:2:" in str(err.value) and "stripe_width=0.2" in str(err.value)


def test_the_kit_finish_mark_is_two_bars_with_a_gap_in_the_centre():
    """Rules summary section 1.2: two bars 20 mm along x 94 mm across, a 74 mm gap in the
    lane's centre, 124 mm of white to each line (20+124+94+74+94+124+20 = 550), 550 mm from
    one end of the 720 mm piece (the entry, our choice); the lap is timed at the mark."""
    lay = parse_layout("@kit = nxp\n" + OVAL)
    track = chain_layout(lay)
    sf = track.start_finish.piece
    bars = sorted(g.bounds for g in sf.marking.geoms)
    assert len(bars) == 2
    (ax0, ay0, ax1, ay1), (bx0, by0, bx1, by1) = bars
    assert (ax1 - ax0, ay1 - ay0, by1 - by0) == pytest.approx((0.02, 0.094, 0.094))
    assert (by0 - ay1, 0.255 - by1, ay0 + 0.255, ax0) == pytest.approx((0.074, 0.124, 0.124, 0.55))
    gate, half = track.finish_gate()
    assert (gate.x_m, gate.y_m) == pytest.approx((0.56, 0.0)) and half == pytest.approx(0.275)
    plain = chain_layout(parse_layout(OVAL)).start_finish.piece   # without the kit: one bar across
    assert plain.marking.geom_type == "Polygon" and plain.ports["finish"].x_m == 0.5


def test_the_wave_is_the_rules_chicane_and_validates_by_its_smoothest_path():
    """Rules summary section 1.2: 1440 mm, R400 arcs, envelope 635.57 mm of the 550 road (a
    swing of 85.57 mm), about two waves; its arcs are tighter than the default car turns
    (0.414 m), the smoothest path through its lane is straight."""
    from pieces import wave
    from pieces.spec import TrackSettings
    from trackgen.build import validate_path as validate

    p = wave(settings=TrackSettings(lane_width_m=0.51, edge_width_m=0.02))
    x0, y0, x1, y1 = p.footprint.bounds
    assert (x1 - x0, y1 - y0) == pytest.approx((1.44, 0.63557), abs=1e-9)
    assert p.ports["exit"].x_m == 1.44 and p.ports["exit"].y_m == 0.0 and p.ports["exit"].yaw_rad == 0.0
    assert p.min_radius_m == math.inf
    from pieces import wave_geometry
    assert wave_geometry(0.72, 0.08557)[1] == pytest.approx(0.400, abs=1e-4)
    assert validate(REPO / "examples" / "kit_wave.txt") == []
    steep = wave(length_m=4.0, swing_m=0.7)   # swings more than its lane: a curving path
    assert 0.0 < steep.min_radius_m < math.inf


@pytest.mark.parametrize("angle_deg", [45.0, 60.0, 120.0, 135.0])
def test_a_crossing_at_another_angle_crosses_at_its_middle_and_keeps_to_its_piece(angle_deg):
    """CROSSROADS angle=A: two equal roads crossing at their middles at A degrees; the side
    road's ports are on its centreline, the piece's footprint stays between its entry and
    exit lines (as every piece's does), and its edge lines are broken where a lane passes."""
    from pieces import crossroads
    from pieces.spec import TrackSettings

    kit = TrackSettings(lane_width_m=0.51, edge_width_m=0.02)
    a = math.radians(angle_deg)
    p = crossroads(angle_rad=a, settings=kit)
    need = 0.55 * (1 + abs(math.cos(a))) / math.sin(a)
    assert p.length_m == pytest.approx(need, rel=1e-12) and p.params["angle_rad"] == a
    c = p.length_m / 2
    for port, sign in (("side_in", -1), ("side_out", 1)):
        q = p.ports[port]
        assert (q.x_m, q.y_m, q.yaw_rad) == pytest.approx((c + sign * c * math.cos(a), sign * c * math.sin(a), a))
    x0, _, x1, _ = p.footprint.bounds
    assert x0 > -1e-9 and x1 < p.length_m + 1e-9
    assert p.lane.intersection(p.edges).area < 1e-12
    centre = shapely.Point(c, 0.0)
    assert p.lane.contains(centre) and not p.edges.intersects(centre.buffer(0.25))
    with pytest.raises(Exception, match="at least 1.3"):
        crossroads(angle_rad=math.radians(45.0), length_m=0.55, settings=kit)


def test_the_90_degree_crossroads_is_unchanged():
    from pieces import crossroads

    p = crossroads()
    assert p.params == {"length_m": 0.6} and p.ports["side_in"].yaw_rad == math.pi / 2
    assert crossroads(angle_rad=math.pi / 2).lane.equals_exact(p.lane, 0.0)


def test_a_kit_figure8_crossing_at_45_degrees_is_followed_straight_on():
    """examples/kit_crossing45.txt: the kit's 0.55 m is for its 90-degree square; a crossing at
    45 degrees takes its own smallest length. The layout closes, validates, and the line
    follower laps it; its laps follow the course through both passes of the crossing."""
    from simrunner.run.runner import drive
    from simrunner.track import load_track

    lay = load_layout(REPO / "examples" / "kit_crossing45.txt")
    assert lay.piece_kwargs(lay.entries[0]) == {"angle_rad": pytest.approx(math.pi / 4)}
    track = load_track(REPO / "examples" / "kit_crossing45.txt")
    r = drive(REPO / "examples" / "line_follower.py", track=track, laps=2, seed=0)
    assert r.outcome == "finished", r.message
    assert all(d >= 0.9 * track.course.length_m for d in r.lap_distances_m)


def test_a_tunnel_shades_its_piece_and_stands_in_the_world(tmp_path):
    """TUNNEL: a straight with a shade over it (its length, the road and walls wide), in the
    built world as roof and walls; the physical camera sees its floor dim."""
    import numpy as np

    from simrunner.sensors.camera import Camera
    from simrunner.sensors.imaging import Imager
    from simrunner.track import load_track
    from trackgen.build import build
    from vehicle.description import CarDescription
    from pieces.pose import Pose2

    text = "@kit = nxp\nSTART_FINISH\nTUNNEL length=1.44 transmission=0.1\nTURN_LEFT x4\nSTRAIGHT x3\nTURN_LEFT x4\n"
    path = tmp_path / "t.txt"
    path.write_text(text)
    (shade,) = chain_layout(load_layout(path)).lighting().shades
    assert (shade.x_m, shade.y_m, shade.length_m, shade.transmission) == pytest.approx((0.72 + 0.72, 0.0, 1.44, 0.1))
    assert shade.width_m == pytest.approx(0.55 + 0.1)
    build(path, tmp_path / "out")
    assert (tmp_path / "out" / "world.sdf").read_text().count('name="tunnel_0_') == 3
    track = load_track(path)
    assert load_track(tmp_path / "out").lighting == track.lighting
    car = CarDescription()
    imager = Imager(Camera(car.camera, track), track.lighting, surface_z_m=track.surface_z_m)
    row = car.camera.default_row
    outside = imager.line(Pose2(0.0, 0.0, 0.0), row, exposure_s=0.01)
    inside = imager.line(Pose2(1.0, 0.0, 0.0), row, exposure_s=0.01)
    assert np.median(inside) < 0.3 * np.median(outside)
