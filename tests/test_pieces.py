"""Track pieces: watertight meshes, disjoint footprints, exact ports, seamless joins."""
import math
import subprocess
import sys

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.affinity import affine_transform

import pieces
from pieces import (CHICANE_LEFT, CHICANE_RIGHT, CROSSROADS, PARAMS, START_FINISH, STRAIGHT,
                    STRAIGHT_SHORT, TURN_LEFT, TURN_RIGHT, Piece, PieceError, PieceType, Pose2,
                    TrackSettings, make_piece, piece_from_layout)
from pieces.mesh import extrude_footprint

ALL_KINDS = list(PieceType)
DEFAULTS = {kind: make_piece(kind) for kind in ALL_KINDS}
TOL_M = 1e-9
# manifold3d's CrossSection snaps coordinates to a 2**-27 m grid (Clipper2): at most
# 3.8e-9 m a vertex, so an area moves by at most ~perimeter * 3.8e-9 m.
SNAP_M = 2.0 ** -28


def parts(piece: Piece):
    return [g for g in (piece.lane, piece.edges, piece.marking) if g is not None]


def meshes(piece: Piece):
    return [m for m in (piece.lane_mesh, piece.edge_mesh, piece.marking_mesh) if m is not None]


def placed(piece: Piece, pose: Pose2):
    return affine_transform(piece.footprint, pose.as_shapely_affine())


@pytest.mark.parametrize("kind", ALL_KINDS, ids=lambda k: k.name)
def test_meshes_watertight_and_volume_matches_area(kind):
    piece = DEFAULTS[kind]
    t = piece.settings.thickness_m
    for geom, mesh in zip(parts(piece), meshes(piece)):
        assert mesh.is_watertight and mesh.is_winding_consistent
        assert mesh.volume == pytest.approx(geom.area * t, rel=1e-6)
        assert mesh.bounds[0][2] == pytest.approx(0.0, abs=1e-12)
        assert mesh.bounds[1][2] == pytest.approx(t, abs=1e-12)
    marked = (START_FINISH, PieceType.SPEED_LIMIT_START, PieceType.SPEED_LIMIT_END)
    assert (piece.marking is None) == (kind not in marked)


@pytest.mark.parametrize("kind", ALL_KINDS, ids=lambda k: k.name)
def test_footprints_valid_and_pairwise_disjoint(kind):
    piece = DEFAULTS[kind]
    ps = parts(piece)
    assert all(g.is_valid and g.area > 0 for g in ps)
    for i, a in enumerate(ps):
        for b in ps[i + 1:]:
            assert a.intersection(b).area < 1e-9
    assert piece.footprint.geom_type == "Polygon"
    assert piece.footprint.area == pytest.approx(sum(g.area for g in ps), rel=1e-12)


def _normal_probe_lengths(piece: Piece, geom, fraction: float):
    """Lengths of the lane/edge cut by a long normal at a centreline vertex near
    ``fraction`` of the way (vertices of an evenly sampled arc: the chord through the two
    neighbours is parallel to the true tangent)."""
    line = piece.centreline
    if len(line) == 2:
        line = np.linspace(line[0], line[1], 301)
    i = min(max(1, round(fraction * (len(line) - 1))), len(line) - 2)
    tangent = line[i + 1] - line[i - 1]
    tangent /= np.linalg.norm(tangent)
    normal = np.array([-tangent[1], tangent[0]])
    probe = shapely.LineString([line[i] - 0.5 * normal, line[i] + 0.5 * normal])
    cut = probe.intersection(geom)
    return sorted(g.length for g in shapely.get_parts(cut))


@pytest.mark.parametrize("kind", ALL_KINDS, ids=lambda k: k.name)
@pytest.mark.parametrize("fraction", [0.1, 0.35, 0.8])
def test_lane_and_edge_widths_perpendicular_to_centreline(kind, fraction):
    piece = DEFAULTS[kind]
    s = piece.settings
    if kind is CROSSROADS:  # lane and edge lines are the main road's own only near its ends
        fraction = {0.1: 0.005, 0.8: 0.995}.get(fraction)
        if fraction is None:
            pytest.skip("inside the crossing the lane is the other road")
    surface = piece.lane if piece.marking is None else shapely.union(piece.lane, piece.marking)  # marks lie on the lane
    assert _normal_probe_lengths(piece, surface, fraction) == pytest.approx([s.lane_width_m], abs=TOL_M)
    assert _normal_probe_lengths(piece, piece.edges, fraction) == pytest.approx([s.edge_width_m] * 2, abs=TOL_M)


@pytest.mark.parametrize("kind", ALL_KINDS, ids=lambda k: k.name)
def test_ports_sit_on_the_footprint_edges(kind):
    """Entry/exit (and side) ports: the centre of a straight edge of width road width,
    perpendicular to the port heading, on the footprint boundary."""
    piece = DEFAULTS[kind]
    s = piece.settings
    assert piece.ports["entry"] == Pose2()
    np.testing.assert_allclose(piece.centreline[0], [0.0, 0.0], atol=0)
    exit_ = piece.ports["exit"]
    np.testing.assert_allclose(piece.centreline[-1], [exit_.x_m, exit_.y_m], atol=TOL_M)
    boundary = piece.footprint.boundary
    names = ["entry", "exit"] + (["side_in", "side_out"] if kind is CROSSROADS else [])
    half = s.road_width_m / 2.0
    for name in names:
        port = piece.ports[name]
        ends = port.apply([[0.0, -half], [0.0, half]])
        edge = shapely.LineString(ends)
        assert boundary.distance(shapely.Point(ends[0])) < TOL_M
        assert boundary.distance(shapely.Point(ends[1])) < TOL_M
        assert edge.difference(boundary.buffer(TOL_M)).length < TOL_M
        # the piece lies ahead of its entry/side_in port, behind its exit/side_out port
        ahead = port.apply([[1e-3, 0.0]])[0]
        inside = piece.footprint.contains(shapely.Point(ahead))
        assert inside == (name in ("entry", "side_in"))


@pytest.mark.parametrize("angle_deg", [10.0, 45.0, 90.0, 135.0, 180.0])
@pytest.mark.parametrize("radius_m", [0.3, 0.8, 2.5])
def test_turn_exit_is_analytic(angle_deg, radius_m):
    a = math.radians(angle_deg)
    for direction, ctor in ((1, pieces.turn_left), (-1, pieces.turn_right)):
        piece = ctor(angle_rad=a, radius_m=radius_m)
        want = Pose2(radius_m * math.sin(a), direction * radius_m * (1 - math.cos(a)), direction * a)
        d_m, d_rad = piece.ports["exit"].distance_to(want)
        assert d_m < TOL_M and d_rad < 1e-12
        assert piece.length_m == pytest.approx(radius_m * a, rel=1e-12)
        # every centreline vertex on the true arc, every chord within the arc tolerance
        centre = np.array([0.0, direction * radius_m])
        r = np.linalg.norm(piece.centreline - centre, axis=1)
        np.testing.assert_allclose(r, radius_m, atol=TOL_M)
        outer = radius_m + piece.settings.road_width_m / 2
        step = a / (len(piece.centreline) - 1)
        assert outer * (1 - math.cos(step / 2)) <= piece.settings.arc_tolerance_m + 1e-15


def test_two_45_turns_equal_one_90_turn():
    q = pieces.turn_left(angle_rad=math.pi / 4)
    h = pieces.turn_left(angle_rad=math.pi / 2)
    d_m, d_rad = (q.ports["exit"] @ q.ports["exit"]).distance_to(h.ports["exit"])
    assert d_m < 1e-12 and d_rad < 1e-12
    r = pieces.turn_right(angle_rad=math.pi / 4)
    a, radius = math.pi / 4, 0.8  # right then left: an S, heading back to 0
    want = Pose2(2 * radius * math.sin(a), -2 * radius * (1 - math.cos(a)), 0.0)
    d_m, d_rad = (r.ports["exit"] @ q.ports["exit"]).distance_to(want)
    assert d_m < 1e-12 and d_rad < 1e-12


def test_straight_exits():
    assert DEFAULTS[STRAIGHT].ports["exit"] == Pose2(1.0, 0.0, 0.0)
    assert DEFAULTS[STRAIGHT_SHORT].ports["exit"] == Pose2(0.5, 0.0, 0.0)
    assert DEFAULTS[START_FINISH].ports["exit"] == Pose2(1.0, 0.0, 0.0)
    assert DEFAULTS[CROSSROADS].ports["exit"] == Pose2(0.6, 0.0, 0.0)
    assert DEFAULTS[STRAIGHT].min_radius_m == math.inf


def test_crossroads_ports_and_broken_edge_lines():
    x = DEFAULTS[CROSSROADS]
    s, c = x.settings, 0.3
    h, e = s.lane_width_m / 2, s.edge_width_m
    assert x.ports["side_in"] == Pose2(c, -c, math.pi / 2)
    assert x.ports["side_out"] == Pose2(c, c, math.pi / 2)
    np.testing.assert_allclose(x.side_centreline, [[c, -c], [c, c]])
    # the side road, travelled the other way
    rev_in, rev_out = x.ports["side_out"].reversed(), x.ports["side_in"].reversed()
    assert rev_in.distance_to(Pose2(c, c, -math.pi / 2))[1] < 1e-12
    assert rev_out.distance_to(Pose2(c, -c, -math.pi / 2))[1] < 1e-12
    # no edge line across either lane: the lanes and the edges only touch
    main_lane = shapely.box(0, -h, 0.6, h)
    side_lane = shapely.box(c - h, -c, c + h, c)
    assert x.edges.intersection(main_lane).area < 1e-12
    assert x.edges.intersection(side_lane).area < 1e-12
    assert x.lane.area == pytest.approx(main_lane.union(side_lane).area, rel=1e-12)
    # four corner stubs; along each edge line, black only over the 0.025 m stub at each end
    assert len(shapely.get_parts(x.edges)) == 4
    for y in (h + e / 2, -h - e / 2):
        along = shapely.LineString([(0, y), (0.6, y)]).intersection(x.edges)
        assert along.length == pytest.approx(0.6 - s.lane_width_m, abs=TOL_M)
        assert len(shapely.get_parts(along)) == 2


def test_chicane_keeps_heading_and_shifts_by_offset():
    for ctor, sign in ((pieces.chicane_left, 1), (pieces.chicane_right, -1)):
        p = ctor(length_m=1.0, offset_m=0.2)
        assert p.ports["exit"].distance_to(Pose2(1.0, sign * 0.2, 0.0)) == (0.0, 0.0)
        theta, radius = pieces.chicane_geometry(1.0, 0.2)
        assert theta == pytest.approx(2 * math.atan(0.2), rel=1e-15)
        assert radius == pytest.approx(1.0 / (2 * math.sin(theta)), rel=1e-15)
        assert p.min_radius_m == radius
        assert p.length_m == pytest.approx(2 * radius * theta, rel=1e-12)
        # monotonic in x, sideways shift only in the travel direction's side
        assert np.all(np.diff(p.centreline[:, 0]) > 0)
        assert np.all(sign * np.diff(p.centreline[:, 1]) >= 0)
        # lane exit edge is perpendicular to +x: heading kept
        lane_exit = p.lane.intersection(shapely.LineString([(1.0, -1), (1.0, 1)]))
        assert lane_exit.length == pytest.approx(p.settings.lane_width_m, abs=TOL_M)


def test_start_finish_marking_cut_from_lane():
    p = DEFAULTS[START_FINISH]
    s = p.settings
    assert p.marking.bounds == pytest.approx((0.475, -s.lane_width_m / 2, 0.525, s.lane_width_m / 2))
    assert p.lane.geom_type == "MultiPolygon"
    assert p.lane.area + p.marking.area == pytest.approx(s.lane_width_m * 1.0, rel=1e-12)
    assert p.ports["finish"] == Pose2(0.5, 0.0, 0.0)
    # a line camera looking across the lane at the finish sees black from edge to edge
    across = shapely.LineString([(0.5, -0.3), (0.5, 0.3)])
    assert across.intersection(p.lane).length == 0.0


THESIS_FIGURE8 = ("CROSSROADS STRAIGHT_SHORT TURN_LEFT TURN_LEFT STRAIGHT STRAIGHT TURN_LEFT TURN_LEFT "
                  "TURN_LEFT TURN_LEFT STRAIGHT STRAIGHT STRAIGHT_SHORT CROSSROADS STRAIGHT_SHORT "
                  "TURN_RIGHT TURN_RIGHT TURN_RIGHT TURN_RIGHT TURN_RIGHT TURN_RIGHT STRAIGHT_SHORT").split()


def test_thesis_figure8_closes_with_pose_algebra():
    pose = Pose2()
    poses = []
    for name in THESIS_FIGURE8:
        piece = DEFAULTS[PieceType[name]]
        pose = pose @ piece.ports["entry"].inverse()
        poses.append(pose)
        pose = pose @ piece.ports["exit"]
    d_m, d_rad = pose.distance_to(Pose2())
    assert d_m < 1e-9 and d_rad < 1e-9
    # the second crossroads is the first one, crossed along its side road (from +y)
    first, second = poses[0], poses[THESIS_FIGURE8.index("CROSSROADS", 1)]
    x = DEFAULTS[CROSSROADS]
    d_m, d_rad = second.distance_to(first @ x.ports["side_out"].reversed())
    assert d_m < 1e-9 and d_rad < 1e-9


def _assert_joined(a_geom, b_geom):
    """No overlap, and no gap: seams agree to float rounding (~1e-16 m after a rotation),
    so unioned on a 1e-9 m grid (1000x finer than the exporter's 1e-6 m) they are one
    polygon without slivers."""
    assert a_geom.intersection(b_geom).area < 1e-9
    joined = shapely.union(a_geom, b_geom, grid_size=1e-9)
    assert joined.geom_type == "Polygon", joined.geom_type
    assert len(joined.interiors) == 0 or all(shapely.Polygon(r).area > 1e-6 for r in joined.interiors)


@pytest.mark.parametrize("first", ALL_KINDS, ids=lambda k: k.name)
def test_adjacent_pieces_neither_overlap_nor_gap(first):
    a = DEFAULTS[first]
    for second in ALL_KINDS:
        b = DEFAULTS[second]
        world_from_b = a.ports["exit"] @ b.ports["entry"].inverse()
        _assert_joined(a.footprint, placed(b, world_from_b))


def test_pieces_join_crossroads_side_ports():
    x = DEFAULTS[CROSSROADS]
    for other in (DEFAULTS[STRAIGHT], DEFAULTS[TURN_RIGHT], DEFAULTS[CHICANE_LEFT]):
        _assert_joined(x.footprint, placed(other, x.ports["side_out"]))
        _assert_joined(x.footprint, placed(other, x.ports["side_in"] @ other.ports["exit"].inverse()))
        _assert_joined(x.footprint, placed(other, x.ports["side_in"].reversed()))


def test_extrude_footprint_of_unioned_track_is_watertight():
    pose, geoms = Pose2(), []
    for name in THESIS_FIGURE8[:13]:
        piece = DEFAULTS[PieceType[name]]
        geoms.append(placed(piece, pose))
        pose = pose @ piece.ports["exit"]
    road = shapely.union_all(geoms, grid_size=1e-6)
    mesh = extrude_footprint(road, 0.01)
    assert mesh.is_watertight
    assert mesh.volume == pytest.approx(road.area * 0.01, rel=1e-6)


def test_meshes_are_lazy_and_pieces_are_values():
    p = pieces.straight(length_m=0.7)
    assert "lane_mesh" not in p.__dict__
    _ = p.lane_mesh
    assert "lane_mesh" in p.__dict__
    assert p == pieces.straight(length_m=0.7) and hash(p) == hash(pieces.straight(length_m=0.7))
    assert p != pieces.straight_short(length_m=0.7)
    with pytest.raises(TypeError):
        p.params["length_m"] = 2.0
    with pytest.raises(ValueError):
        p.centreline[0, 0] = 1.0
    with pytest.raises(AttributeError):
        p.length_m = 3.0


def test_piece_from_layout_converts_degrees_and_checks_names():
    p = piece_from_layout(TURN_LEFT, {"angle": 90, "radius": 1.0})
    assert p.params["angle_rad"] == pytest.approx(math.pi / 2, rel=1e-15)
    assert PARAMS[TURN_LEFT]["angle"].unit == "deg"
    assert set(PARAMS[CHICANE_RIGHT]) == {"length", "offset"}
    with pytest.raises(PieceError, match="no parameter 'radius'.*length"):
        piece_from_layout(STRAIGHT, {"radius": 1.0})
    with pytest.raises(PieceError, match=r"angle=270 deg: expected \[0.001, 180\] deg"):
        piece_from_layout(TURN_RIGHT, {"angle": 270})
    with pytest.raises(PieceError, match="no parameter 'angle_deg'"):
        make_piece(TURN_RIGHT, angle_deg=30)
    for kind in ALL_KINDS:  # defaults in PARAMS give the default pieces
        defaults = {name: spec.default for name, spec in PARAMS[kind].items()}
        assert piece_from_layout(kind, defaults) == DEFAULTS[kind]
    assert TrackSettings.from_layout({"lane_width": 0.5}).lane_width_m == 0.5
    with pytest.raises(PieceError, match="unknown track setting 'lane'"):
        TrackSettings.from_layout({"lane": 0.5})
    with pytest.raises(PieceError, match=r"^thickness=-1 m: expected \[1e-06, 10\] m"):
        TrackSettings.from_layout({"thickness": -1})
    # limits that depend on the settings are reported in layout names too
    with pytest.raises(PieceError, match=r"^radius=0.2 m: expected \(0.295, inf\) m"):
        piece_from_layout(TURN_LEFT, {"radius": 0.2})
    with pytest.raises(PieceError, match=r"^length=0.5 m: expected \[0.59"):
        piece_from_layout(CROSSROADS, {"length": 0.5})
    with pytest.raises(PieceError, match=r"^offset=0.3 with length=0.3: arc radius"):
        piece_from_layout(CHICANE_RIGHT, {"offset": 0.3, "length": 0.3})
    with pytest.raises(PieceError, match=r"^mark_length=2 m"):
        piece_from_layout(START_FINISH, {"mark_length": 2})


BAD_CALLS = [
    (lambda: pieces.straight(length_m=0.0), "length_m=0"),
    (lambda: pieces.straight_short(length_m=-1.0), "length_m=-1"),
    (lambda: pieces.straight(length_m=math.nan), "length_m=nan"),
    (lambda: pieces.turn_left(angle_rad=0.0), r"angle_rad=0 rad: expected \(0, 3.14159\]"),
    (lambda: pieces.turn_right(angle_rad=3.2), "angle_rad=3.2"),
    (lambda: pieces.turn_left(radius_m=0.29), r"radius_m=0.29 m: expected \(0.295.*half the road"),
    (lambda: pieces.turn(direction=0), "direction=0"),
    (lambda: pieces.chicane_left(offset_m=0.0), "offset_m=0"),
    (lambda: pieces.chicane_left(length_m=0.3, offset_m=0.3), "offset_m=0.3.*radius"),
    (lambda: pieces.crossroads(length_m=0.5), r"length_m=0.5 m: expected \[0.59.*road width"),
    (lambda: pieces.start_finish(mark_length_m=1.0), "mark_length_m=1"),
    (lambda: TrackSettings(lane_width_m=0.0), "lane_width_m=0"),
    (lambda: TrackSettings(edge_width_m=-0.02), "edge_width_m=-0.02"),
    (lambda: TrackSettings(thickness_m=0.0), "thickness_m=0"),
    (lambda: TrackSettings(arc_tolerance_m=0.06), r"arc_tolerance_m=0.06 m: expected \[1e-05, 0.05\]"),
    (lambda: pieces.straight(length_m="long"), "length_m='long'"),
    (lambda: extrude_footprint(shapely.box(0, 0, 1, 1), 0.0), "thickness_m=0"),
]


@pytest.mark.parametrize("call,match", BAD_CALLS, ids=[m for _, m in BAD_CALLS])
def test_invalid_parameters_raise_piece_error_naming_them(call, match):
    with pytest.raises(PieceError, match=match):
        call()


def test_pieces_does_not_import_physics_or_opencv():
    code = "import sys, pieces; pieces.straight().lane_mesh; print(sorted({'dartpy', 'cv2'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_keyword_only():
    with pytest.raises(TypeError):
        pieces.straight(1.0)  # noqa


# ---------------------------------------------------------------- property tests

track_settings = st.builds(
    TrackSettings,
    lane_width_m=st.floats(0.2, 0.8), edge_width_m=st.floats(0.005, 0.05),
    thickness_m=st.floats(0.002, 0.05), arc_tolerance_m=st.floats(0.0005, 0.05))


@st.composite
def random_pieces(draw):
    s = draw(track_settings)
    kind = draw(st.sampled_from(ALL_KINDS))
    road = s.road_width_m
    if kind in (STRAIGHT, STRAIGHT_SHORT, PieceType.EXTENDER):
        params = {"length_m": draw(st.floats(0.01, 3.0))}
    elif kind is START_FINISH:
        length = draw(st.floats(0.1, 3.0))
        params = {"length_m": length, "mark_length_m": draw(st.floats(0.01, 0.9)) * length}
    elif kind is CROSSROADS:
        params = {"length_m": road + draw(st.floats(0.0, 1.0))}
        if draw(st.booleans()):  # a crossing at another angle: at least its own smallest length
            a = math.radians(draw(st.floats(30.0, 150.0)))
            params = {"angle_rad": a,
                      "length_m": road * (1 + abs(math.cos(a))) / math.sin(a) + draw(st.floats(1e-6, 1.0))}
    elif kind is PieceType.WAVE:
        length = draw(st.floats(0.3, 3.0))
        swing = draw(st.floats(0.001, 0.04)) * length
        if pieces.wave_geometry(length / 2, swing)[1] <= road / 2 + 1e-3:
            swing = (length / 2) ** 2 / (16.0 * (road + 1.0))  # gentle: R ~ road + 1 m
        params = {"length_m": length, "swing_m": swing}
    elif kind in (PieceType.SPEED_LIMIT_START, PieceType.SPEED_LIMIT_END):
        length = draw(st.floats(0.1, 3.0))
        params = {"length_m": length, "stripe_length_m": draw(st.floats(0.05, 0.95)) * length,
                  "stripe_width_m": draw(st.floats(0.05, 0.95)) * s.lane_width_m / 7}
    elif kind is PieceType.TUNNEL:
        params = {"length_m": draw(st.floats(0.01, 3.0)), "transmission": draw(st.floats(0.0, 1.0))}
    elif kind is PieceType.HILL:
        length = draw(st.floats(0.01, 3.0))
        params = {"length_m": length, "height_m": draw(st.floats(1e-4, 1.0)) * length / math.pi}
    elif kind in (TURN_LEFT, TURN_RIGHT):
        params = {"radius_m": road / 2 + draw(st.floats(0.01, 3.0)),
                  "angle_rad": draw(st.floats(0.01, math.pi))}
    else:
        length = draw(st.floats(0.3, 3.0))
        offset = draw(st.floats(0.01, 0.6))
        if pieces.chicane_geometry(length, offset)[1] <= road / 2 + 1e-3:
            offset = 0.05 * length  # gentle enough for any drawn length (R ~ 5 * length)
        params = {"length_m": length, "offset_m": offset}
    return make_piece(kind, s, **params)


def expected_exit(p: Piece) -> Pose2:
    q = p.params
    if p.kind in (TURN_LEFT, TURN_RIGHT):
        d = 1 if p.kind is TURN_LEFT else -1
        r, a = q["radius_m"], q["angle_rad"]
        return Pose2(r * math.sin(a), d * r * (1 - math.cos(a)), d * a)
    if p.kind in (CHICANE_LEFT, CHICANE_RIGHT):
        return Pose2(q["length_m"], (1 if p.kind is CHICANE_LEFT else -1) * q["offset_m"], 0.0)
    return Pose2(q["length_m"], 0.0, 0.0)


@settings(max_examples=40, deadline=None)
@given(random_pieces())
def test_random_valid_pieces_watertight_with_exact_ports(p):
    d_m, d_rad = p.ports["exit"].distance_to(expected_exit(p))
    assert d_m < TOL_M and d_rad < 1e-12
    np.testing.assert_allclose(p.centreline[-1], [p.ports["exit"].x_m, p.ports["exit"].y_m], atol=TOL_M)
    t = p.settings.thickness_m
    ps = parts(p)
    for i, (geom, mesh) in enumerate(zip(ps, meshes(p))):
        assert geom.is_valid
        assert mesh.is_watertight
        assert abs(mesh.volume - geom.area * t) <= t * (1e-6 * geom.area + SNAP_M * 2 * geom.length)
        for other in ps[i + 1:]:
            assert geom.intersection(other).area < 1e-9
    # joins itself seamlessly
    _assert_joined(p.footprint, placed(p, p.ports["exit"]))




@settings(max_examples=60, deadline=None)
@given(st.sampled_from(ALL_KINDS), st.data())
def test_invalid_layout_values_raise_with_the_name(kind, data):
    name = data.draw(st.sampled_from(sorted(PARAMS[kind])))
    spec = PARAMS[kind][name]
    below = st.one_of(st.floats(max_value=spec.lo, exclude_max=not spec.lo_open), st.just(math.nan),
                      st.just(math.inf))  # (0 is a valid mark_gap: below its range, not <= 0)
    value = data.draw(st.one_of(below, st.floats(min_value=spec.hi, exclude_min=not spec.hi_open)
                                if math.isfinite(spec.hi) else below))
    with pytest.raises(PieceError, match=f"^{name}="):
        piece_from_layout(kind, {name: value})
