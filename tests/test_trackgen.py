"""trackgen: chaining (thesis figure 8), validation problems at the right lines, build
outputs read back, CLI exit codes, bad input and atomic writes."""
from __future__ import annotations

import json
import math
import re
import struct
import tempfile
from pathlib import Path

import numpy as np
import pytest
import shapely
import trimesh
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings, strategies as st

from pieces import CROSSROADS, STRAIGHT, STRAIGHT_SHORT, TURN_LEFT, TURN_RIGHT, Pose2
from trackgen import LayoutError, TrackError, TrackGenerator, chain, load_layout, parse_layout
from trackgen.build import OPTIONAL_TRACK_JSON_KEYS, OutputError, TRACK_JSON_KEYS, ValidationFailed, build, check_layout
from trackgen.chain import START_BEFORE_FINISH_M
from trackgen.cli import main
from trackgen.validate import errors
from vehicle.description import CarDescription, Steering

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
FIG8 = EXAMPLES / "thesis_figure8.txt"
OVAL = EXAMPLES / "oval_start.txt"
BROKEN = EXAMPLES / "broken.txt"
THESIS_SEQUENCE = ("CROSSROADS STRAIGHT_SHORT TURN_LEFT TURN_LEFT STRAIGHT STRAIGHT TURN_LEFT "
                   "TURN_LEFT TURN_LEFT TURN_LEFT STRAIGHT STRAIGHT STRAIGHT_SHORT CROSSROADS "
                   "STRAIGHT_SHORT TURN_RIGHT TURN_RIGHT TURN_RIGHT TURN_RIGHT TURN_RIGHT "
                   "TURN_RIGHT STRAIGHT_SHORT").split()


def fig8_lines(**replace: str) -> list[str]:
    """The thesis sequence, one piece per line (line i+1 = piece i); ``replace`` maps
    'L<line>' to a replacement line."""
    lines = list(THESIS_SEQUENCE)
    for key, text in replace.items():
        lines[int(key[1:]) - 1] = text
    return lines


def check_text(text: str, car: CarDescription | None = None):
    return check_layout(parse_layout(text, path="t.txt"), car)


def problems_of(text: str, check: str, car=None) -> list:
    return [p for p in check_text(text, car).problems if p.check == check]


# -- chaining ----------------------------------------------------------------------------------
def test_thesis_figure8_closes_through_one_crossroads():
    layout = load_layout(FIG8)
    assert [e.kind.name for e in layout.entries] == THESIS_SEQUENCE
    track = chain(layout)
    err_m, err_rad = track.closure_error()
    assert err_m < 1e-9 and err_rad < 1e-9
    assert len(track.passes) == 22 and len(track.physical) == 21
    assert sum(p.kind is CROSSROADS and not p.revisit for p in track.passes) == 1
    (r,) = track.reentries
    assert (r.index, r.of_index, r.pass_number) == (13, 0, 2)
    assert r.error_m < 1e-9 and r.error_rad < 1e-9
    # The second pass runs the side road downwards through the crossroads centre (0.3, 0).
    second = track.passes[13]
    assert second.entry_world.distance_to(Pose2(0.3, 0.3, -math.pi / 2))[0] < 1e-12
    assert second.exit_world.distance_to(Pose2(0.3, -0.3, -math.pi / 2))[0] < 1e-12
    checked = check_layout(layout)
    assert checked.ok
    assert [p.check for p in checked.problems] == ["start_finish"]   # the warning only
    # The crossroads is in the lane union once: union area == sum of the physical lanes.
    lanes = track.world_footprints["lane"]
    assert checked.geometry.lane.area == pytest.approx(sum(g.area for g in lanes), abs=1e-6)
    assert shapely.intersection(checked.geometry.lane, checked.geometry.edges).area < 1e-9


def test_python_api_matches_layout_file():
    gen = TrackGenerator(name="thesis_figure8")
    kinds = {"CROSSROADS": CROSSROADS, "STRAIGHT_SHORT": STRAIGHT_SHORT, "STRAIGHT": STRAIGHT,
             "TURN_LEFT": TURN_LEFT, "TURN_RIGHT": TURN_RIGHT}
    for name in THESIS_SEQUENCE:
        gen.add_piece(kinds[name])
    track = gen.build()
    ref = chain(load_layout(FIG8))
    for a, b in zip(track.passes, ref.passes):
        assert a.entry_world.distance_to(b.entry_world)[0] < 1e-12
    assert track.closure_error()[0] < 1e-9
    custom = TrackGenerator().add_piece(TURN_LEFT, angle_deg=90, radius_m=0.6)
    custom.add_piece(TURN_LEFT, angle_rad=math.pi / 2, radius_m=0.6)
    t = custom.build()
    assert t.end_pose.distance_to(Pose2(0.0, 1.2, math.pi))[0] < 1e-12


def test_python_api_errors_point_at_the_call():
    gen = TrackGenerator()
    with pytest.raises(LayoutError) as info:
        gen.add_piece(TURN_LEFT, angle_deg=400)
    assert info.value.path == __file__
    assert "TURN_LEFT angle_deg=400: expected 0.001 <= angle <= 180 (deg)" in info.value.message
    with pytest.raises(LayoutError, match="unknown parameter 'angle'"):
        gen.add_piece(TURN_LEFT, angle=90)
    with pytest.raises(LayoutError, match="empty track"):
        gen.build()


def test_start_finish_start_pose_and_gate():
    track = chain(load_layout(OVAL))
    gate, half = track.finish_gate()
    assert gate.distance_to(Pose2(0.5, 0.0, 0.0)) == (0.0, 0.0)
    assert half == pytest.approx(0.55 / 2 + 0.02)
    assert track.car_start_pose().distance_to(Pose2(0.5 - START_BEFORE_FINISH_M, 0, 0))[0] < 1e-12
    assert check_layout(track.layout).problems == []


# -- validation: each problem at its line -------------------------------------------------------
def test_non_closing_points_at_last_line():
    probs = check_layout(load_layout(BROKEN)).problems
    (p,) = errors(probs)
    last_line = max(e.line for e in load_layout(BROKEN).entries)
    assert p.check == "closure" and p.line == last_line
    assert str(p).startswith(f"{BROKEN}:{last_line}: track does not close")
    assert "misses the start pose by 1.000 m / 0.0 deg" in str(p)


def test_overlap_flagged_at_the_later_piece():
    # Line 14: a straight instead of the second CROSSROADS runs over the first one (line 1).
    text = "\n".join(fig8_lines(L14="STRAIGHT length=0.6"))
    (p,) = problems_of(text, "overlap")
    assert p.line == 14
    assert "STRAIGHT (piece 14) overlaps CROSSROADS (piece 1, line 1)" in p.message
    area = float(p.message.split(" by ")[1].split(" m^2")[0])
    assert area == pytest.approx(0.59 * 0.6, rel=0.01)   # the straight lies on the crossroads
    assert not problems_of(text, "closure")


def test_too_tight_turn_for_the_car():
    square = "\n".join(["STRAIGHT", "TURN_LEFT angle=90 radius=0.35"] * 4)
    probs = problems_of(square, "turn_radius")
    assert [p.line for p in probs] == [2, 4, 6, 8]
    r_min = CarDescription().min_turn_radius_m
    assert 0.35 < r_min < 0.8
    assert (f"centreline radius 0.350 m is tighter than the car's minimum turning radius "
            f"{r_min:.3f} m") in probs[0].message
    # The default 0.8 m turns fail for a car that steers at most 0.2 rad (R = 0.175/tan 0.2).
    stiff = CarDescription().replace(steering=Steering(limit_rad=0.2))
    assert stiff.min_turn_radius_m > 0.8
    probs = problems_of(FIG8.read_text(), "turn_radius", car=stiff)
    assert len(probs) == 12 and all("TURN_" in p.message for p in probs)


def test_two_start_finish():
    text = "START_FINISH\nSTART_FINISH\nSTRAIGHT\nTURN_LEFT x4\nSTRAIGHT x3\nTURN_LEFT x4\n"
    (p,) = problems_of(text, "start_finish")
    assert p.line == 2 and not p.warning
    assert "second START_FINISH (piece 2; the first is on line 1)" in p.message
    assert not errors(check_text(text).problems)[1:]


def test_crossroads_reentry_miss():
    text = "\n".join(fig8_lines(L13="STRAIGHT_SHORT length=0.62"))
    probs = problems_of(text, "reentry")
    (p,) = probs
    assert p.line == 14
    assert "CROSSROADS re-entry misses side port of the crossroads on line 1 by 0.120 m / 0.0 deg" \
        in p.message
    assert "(tolerance 1e-06 m / 1e-06 rad)" in p.message
    # where it arrives, in the port's frame, and the fix (a straight 0.12 m too long before it)
    assert p.message.endswith("it arrives 0.120 m past the port and 0.000 m to its right, heading 0.0 deg "
                              "right of it; the pieces before it are 0.120 m too long (along the side road)")


def test_crossroads_reentry_miss_beside_the_port_names_the_straights():
    """A straight across the side road's direction too long (line 2, before the upper loop)
    moves the arrival beside the port: the fix names it, as the closure check names straights."""
    text = "\n".join(fig8_lines(L2="STRAIGHT_SHORT length=0.62"))
    (p,) = problems_of(text, "reentry")
    assert p.line == 14
    assert p.message.endswith("it arrives 0.000 m past the port and 0.120 m to its left, heading 0.0 deg right "
                              "of it; the pieces heading 0.0 deg (line 2) are 0.120 m too long in total")


def test_crossroads_three_passes_and_different_params():
    text = "\n".join(fig8_lines(L14="CROSSROADS length=0.7"))
    (p,) = problems_of(text, "reentry")
    assert p.line == 14 and "differs from the crossroads on line 1" in p.message


def test_no_start_finish_is_only_a_warning():
    (p,) = check_layout(load_layout(FIG8)).problems
    assert p.warning
    assert str(p) == (f"{FIG8}:{load_layout(FIG8).entries[0].line}: warning: no START_FINISH "
                      "piece: the simulator then times laps at the start pose")


# -- build outputs -----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def built_oval(tmp_path_factory):
    out = tmp_path_factory.mktemp("b") / "oval"
    result = build(OVAL, out)
    return out, result


def _png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", head[16:24])


def test_build_round_trip(built_oval):
    out, result = built_oval
    doc = json.loads((out / "track.json").read_text())
    assert tuple(k for k in doc if k not in OPTIONAL_TRACK_JSON_KEYS) == TRACK_JSON_KEYS
    assert set(OPTIONAL_TRACK_JSON_KEYS) <= set(doc)
    assert doc["format"] == "nxpcup-track/1" and doc["name"] == "oval_start"
    assert doc["layout"] == str(OVAL)
    layout = load_layout(OVAL)
    assert [p["line"] for p in doc["pieces"]] == [e.line for e in layout.entries]
    assert doc["pieces"][0] == {"index": 0, "kind": "START_FINISH", "line": 5,
                                "params": {"length_m": 1.0, "mark_length_m": 0.05},
                                "pose": [0.0, 0.0, 0.0], "revisit": False}
    assert doc["start_pose"] == pytest.approx([0.2, 0.0, 0.0])
    assert doc["finish_gate"]["pose"] == pytest.approx([0.5, 0.0, 0.0])
    assert doc["surface_z_m"] == pytest.approx(0.01)
    cl = np.array(doc["centreline"])
    assert cl.shape[1] == 2 and np.hypot(*(cl[-1] - cl[0])) < 0.2   # loop, not repeated
    seg = np.hypot(*np.diff(np.vstack([cl, cl[:1]]), axis=0).T).sum()
    assert seg == pytest.approx(doc["length_m"], rel=1e-3)
    lane = shapely.Polygon(doc["lane_polygon"]["exterior"], doc["lane_polygon"]["interiors"])
    road = shapely.Polygon(doc["road_polygon"]["exterior"], doc["road_polygon"]["interiors"])
    assert road.contains(lane.buffer(-1e-4))
    assert road.area - lane.area == pytest.approx(2 * 0.02 * doc["length_m"] + 0.05 * 0.55, rel=0.02)
    mesh_dir = out / "models" / "oval_start" / "meshes"
    for role in ("lane", "edges", "markings"):
        mesh = trimesh.load(mesh_dir / f"{role}.stl", file_type="stl", force="mesh")
        assert mesh.is_watertight and mesh.is_winding_consistent, role
        assert mesh.bounds[:, 2] == pytest.approx([0.0, 0.01], abs=1e-6)
    lane_mesh = trimesh.load(mesh_dir / "lane.stl", force="mesh")
    assert lane_mesh.volume == pytest.approx(lane.area * 0.01, rel=1e-4)
    for f in ("world.sdf", "models/oval_start/model.sdf", "models/nxp_cup_car/model.sdf"):
        assert (out / f).is_file(), f
    w, h = _png_size(out / "preview.png")
    assert (w, h) == result.preview_size_px and max(w, h) == 1200 and min(w, h) > 300
    assert not list(out.parent.glob(".*"))      # no temporary folders left


def test_build_deterministic(built_oval, tmp_path):
    out, _ = built_oval
    again = tmp_path / "oval"
    build(OVAL, again)
    for f in ("track.json", "world.sdf", "models/oval_start/meshes/lane.stl",
              "models/oval_start/meshes/edges.stl"):
        assert (again / f).read_bytes() == (out / f).read_bytes(), f


def test_fig8_build_has_no_markings_and_validates_as_folder(tmp_path):
    out = tmp_path / "fig8"
    build(FIG8, out)
    meshes = sorted(p.name for p in (out / "models" / "thesis_figure8" / "meshes").iterdir())
    assert meshes == ["edges.stl", "lane.stl"]
    doc = json.loads((out / "track.json").read_text())
    assert doc["finish_gate"] is None and doc["start_pose"] == [0.0, 0.0, 0.0]
    assert [p["revisit"] for p in doc["pieces"]].count(True) == 1
    res = CliRunner().invoke(main, ["validate", str(out), "--no-sdf-check"])
    assert res.exit_code == 0, res.output
    (out / "models" / "thesis_figure8" / "meshes" / "lane.stl").write_bytes(b"\0" * 84)
    res = CliRunner().invoke(main, ["validate", str(out), "--no-sdf-check"])
    assert res.exit_code == 2 and "lane.stl: mesh has no triangles" in res.output  # as drive


def test_build_refuses_failing_layout_and_existing_folder(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(ValidationFailed) as info:
        build(BROKEN, out)
    assert "track does not close" in str(info.value)
    assert not out.exists() and list(tmp_path.iterdir()) == []
    out.mkdir()
    (out / "keep.txt").write_text("x")
    with pytest.raises(OutputError, match=r"already exists \(use --force to replace it\)"):
        build(OVAL, out)
    assert (out / "keep.txt").exists()
    build(OVAL, out, force=True)
    assert not (out / "keep.txt").exists() and (out / "track.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_unwritable_output_folder(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(OutputError, match=r"cannot write output folder"):
        build(OVAL, blocker / "sub" / "out")
    res = CliRunner().invoke(main, ["build", str(OVAL), "-o", str(blocker / "out")])
    assert res.exit_code == 2
    assert len(res.output.strip().splitlines()) == 1 and "Traceback" not in res.output
    assert "cannot write output folder" in res.output


# -- CLI ---------------------------------------------------------------------------------------
def test_cli_exit_codes(tmp_path):
    run = CliRunner().invoke
    res = run(main, ["validate", str(FIG8)])
    assert res.exit_code == 0 and "warning: no START_FINISH" in res.output
    res = run(main, ["validate", str(BROKEN)])
    assert res.exit_code == 1 and f"{BROKEN}:12: track does not close" in res.output
    res = run(main, ["build", str(BROKEN), "-o", str(tmp_path / "b")])
    assert res.exit_code == 1 and not (tmp_path / "b").exists()
    res = run(main, ["build", str(OVAL), "-o", str(tmp_path / "o")])
    assert res.exit_code == 0 and (tmp_path / "o" / "world.sdf").is_file()
    res = run(main, ["build", str(OVAL), "-o", str(tmp_path / "o")])
    assert res.exit_code == 2 and "already exists" in res.output
    res = run(main, ["validate", str(tmp_path / "missing.txt")])
    assert res.exit_code == 2 and "cannot read layout" in res.output
    res = run(main, ["validate", str(tmp_path)])
    assert res.exit_code == 2 and "expected world.sdf, one *.world file or model.config" in res.output
    car = tmp_path / "car.toml"
    car.write_text("[steering]\nlimit_rad = 0.2\n")
    res = run(main, ["validate", str(FIG8), "--car", str(car)])
    assert res.exit_code == 1 and "tighter than the car's minimum turning radius" in res.output
    car.write_text("[steering]\nlimit_rad = 'a lot'\n")
    res = run(main, ["validate", str(FIG8), "--car", str(car)])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1


@pytest.mark.parametrize("content, pattern", [
    (b"STRAIGHT\nTRUN_LEFT\n", r"bad.txt:2: unknown piece 'TRUN_LEFT'"),
    (b"TURN_LEFT angle=400\n", r"bad.txt:1: TURN_LEFT angle=400: expected 0.001 <= angle <= 180"),
    (b"TURN_LEFT radius=abc\n", r"bad.txt:1: TURN_LEFT radius=abc: expected a number"),
    (b"", r"bad.txt:1: empty layout"),
    (bytes(range(256)), r"bad.txt:1: not a text layout file"),
    (b"STRAIGHT x100000\n", r"bad.txt:1: STRAIGHT x100000: expected a repeat count"),
    (b"STRAIGHT x1000\n" * 11, r"bad.txt:11: too many pieces"),
])
@pytest.mark.parametrize("command", ["validate", "build"])
def test_cli_bad_input_one_line_no_traceback(tmp_path, content, pattern, command):
    bad = tmp_path / "bad.txt"
    bad.write_bytes(content)
    args = [command, str(bad)] + (["-o", str(tmp_path / "out")] if command == "build" else [])
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.output
    assert re.search(pattern, lines[0]), lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.txt"]


def test_cli_non_closing_build_writes_nothing(tmp_path):
    res = CliRunner().invoke(main, ["build", str(BROKEN), "-o", str(tmp_path / "x")])
    assert res.exit_code == 1
    assert f"{BROKEN}:12: track does not close" in res.output
    assert list(tmp_path.iterdir()) == []


# -- property: build writes nothing on failure --------------------------------------------------
_LINES = st.lists(st.sampled_from([
    "STRAIGHT", "STRAIGHT_SHORT", "TURN_LEFT", "TURN_RIGHT x2", "CROSSROADS", "CHICANE_LEFT",
    "START_FINISH", "TURN_LEFT angle=90", "TURN_LEFT radius=0.3", "TRUN_LEFT", "angle=5",
    "STRAIGHT x0", "@scale = 2", "# c", "",
]), max_size=8)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(lines=_LINES, garbage=st.binary(max_size=16))
def test_property_build_failure_writes_nothing(lines, garbage):
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        src = tmp / "in.txt"
        src.write_bytes("\n".join(lines).encode() + (garbage if len(lines) % 3 == 0 else b""))
        n_lines = src.read_bytes().count(b"\n") + 1
        out = tmp / "out"
        try:
            build(src, out)
        except ValidationFailed as exc:
            assert all(1 <= p.line <= n_lines for p in exc.problems)
            assert all(str(p).startswith(f"{src}:{p.line}: ") for p in exc.problems)
        except TrackError as exc:
            assert isinstance(exc, LayoutError) and 1 <= exc.line <= n_lines
            assert str(exc).startswith(f"{src}:{exc.line}: ")
        else:
            assert (out / "track.json").is_file()
            return
        assert sorted(p.name for p in tmp.iterdir()) == ["in.txt"]


def test_a_road_narrower_than_the_car_is_an_error(tmp_path):
    """The car would stand off the road at t = 0 (issue 50, fault injection)."""
    from trackgen import load_layout
    from trackgen.build import check_layout

    path = tmp_path / "narrow.txt"
    path.write_text("@lane_width = 0.001\nSTART_FINISH\nTURN_LEFT angle=180\nSTRAIGHT\nTURN_LEFT angle=180\n")
    problems = [str(p) for p in check_layout(load_layout(path)).problems]
    assert any(p.startswith(f"{path}:1: the road is 0.041 m wide") and "narrower than the car" in p
               for p in problems), problems  # the @lane_width line
    path.write_text("START_FINISH\n@edge_width = 0.001\n@lane_width = 0.001\nTURN_LEFT angle=180\n"
                    "STRAIGHT\nTURN_LEFT angle=180\n")
    assert [p for p in map(str, check_layout(load_layout(path)).problems) if "the road is" in p][0].startswith(
        f"{path}:3: the road is 0.003 m wide")
    # a road wide enough as written, shrunk by @scale: the @scale line, not the @lane_width one
    path.write_text("@lane_width = 0.55\n@scale = 0.1\nSTART_FINISH\nTURN_LEFT angle=180\nSTRAIGHT\n"
                    "TURN_LEFT angle=180\n")
    assert [p for p in map(str, check_layout(load_layout(path)).problems) if "the road is" in p][0].startswith(
        f"{path}:2: the road is 0.059 m wide (@lane_width 0.055 m and two @edge_width 0.002 m lines, after "
        "@scale 0.1), narrower")
    path.write_text("@lane_width = 0.2\nSTART_FINISH\nTURN_LEFT angle=180\nSTRAIGHT\nTURN_LEFT angle=180\n")
    assert not [p for p in check_layout(load_layout(path)).problems if p.check == "road_width"]
