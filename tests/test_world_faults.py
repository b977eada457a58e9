"""Malformed worlds (issue 13, items 14-15): each is refused by ``trackgen validate`` and by
``simrunner drive`` (and by the library calls behind them) with the same one line, exit 2,
no traceback, in bounded time and memory; nothing outside the world's folder and the model
path is read.

Every bad world is made in ``tmp_path`` from one built oval (``examples/oval_start.txt``),
in two forms: as ``trackgen build`` wrote it (with track.json) and as an imported Gazebo
world (track.json removed: ``validate`` then measures the road, ``worlds``' own checks).
"""
from __future__ import annotations

import os
import shutil
import struct
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from simrunner.cli import main as simrunner_main
from simrunner.track import TrackLoadError, load_track
from trackgen.build import build, validate_path
from trackgen.cli import main as trackgen_main
from worlds import WorldError
from worlds import mesh_read, sdf_read, sdf_xml

ROOT = Path(__file__).resolve().parents[1]
CONTROLLER = ROOT / "examples" / "line_follower.py"
SECRET = "TOP-SECRET-LINE do not echo"
MODEL = "oval_start"


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("base") / "oval"
    build(ROOT / "examples" / "oval_start.txt", out, preview=False)
    return out


@pytest.fixture(params=["trackgen", "imported"])
def world(request, built, tmp_path) -> Path:
    """A fresh copy of the built oval (``imported``: without track.json)."""
    out = tmp_path / "w" / "oval"
    shutil.copytree(built, out)
    if request.param == "imported":
        (out / "track.json").unlink()
    (tmp_path / "secret.txt").write_text(SECRET + "\n")
    (tmp_path / "outside.stl").write_bytes((out / "models" / MODEL / "meshes" / "lane.stl").read_bytes())
    return out


# -- helpers that damage a world -------------------------------------------------------------
def _mesh(world: Path, role: str = "lane") -> Path:
    return world / "models" / MODEL / "meshes" / f"{role}.stl"


def _model_sdf(world: Path) -> Path:
    return world / "models" / MODEL / "model.sdf"


def _sub_in(path: Path, old: str, new: str, count: int = 1) -> None:
    text = path.read_text()
    assert old in text, (old, path)
    path.write_text(text.replace(old, new, count))


def _add_to_world(world: Path, xml: str) -> None:
    _sub_in(world / "world.sdf", "</world>", xml + "</world>")


def _write_model(folder: Path, body: str, name: str | None = None) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    name = name or folder.name
    (folder / "model.config").write_text(
        f"<?xml version='1.0'?><model><name>{name}</name><sdf version='1.6'>model.sdf</sdf></model>")
    (folder / "model.sdf").write_text(f"<?xml version='1.0'?><sdf version='1.6'>"
                                      f"<model name='{name}'>{body}</model></sdf>")


def _binary_stl(tris: np.ndarray) -> bytes:
    tris = np.asarray(tris, dtype="<f4").reshape(-1, 3, 3)
    rec = np.zeros(len(tris), dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = tris
    return b"\0" * 80 + struct.pack("<I", len(tris)) + rec.tobytes()


def _lane_triangles(world: Path) -> np.ndarray:
    return mesh_read.read_triangles(_mesh(world))


def self_include(w):
    _write_model(w / "models" / "loop_a", "<include><uri>model://loop_a</uri></include>")
    _add_to_world(w, "<include><uri>model://loop_a</uri></include>")


def mutual_include(w):
    _write_model(w / "models" / "loop_a", "<include><uri>model://loop_b</uri></include>")
    _write_model(w / "models" / "loop_b", "<include><uri>model://loop_a</uri></include>")
    _add_to_world(w, "<include><uri>model://loop_a</uri></include>")


def include_bomb(w):  # 2**20 includes through 20 models that each include the next twice
    for i in range(20):
        inc = f"<include><uri>model://m{i + 1}</uri></include>" * 2 if i < 19 else ""
        _write_model(w / "models" / f"m{i}", inc)
    _add_to_world(w, "<include><uri>model://m0</uri></include>")


def deep_nesting(w):
    _add_to_world(w, "<model name='n'>" * 5000 + "</model>" * 5000)


def nesting_40_models(w):  # within the XML depth limit, over the model nesting limit
    _add_to_world(w, "".join(f"<model name='n{i}'>" for i in range(40)) + "</model>" * 40)


def link_pose_loop(w):
    _add_to_world(w, "<model name='links'><link name='a'><pose relative_to='b'>0 0 0 0 0 0</pose></link>"
                     "<link name='b'><pose relative_to='a'>0 0 0 0 0 0</pose></link></model>")


def huge_coordinate(w):
    tris = _lane_triangles(w).copy()
    tris[0, 0, :2] = 1e6
    _mesh(w).write_bytes(_binary_stl(tris))


def nan_vertex(w):
    tris = _lane_triangles(w).copy()
    tris[3, 1, 0] = np.nan
    _mesh(w).write_bytes(_binary_stl(tris))


def truncated_binary_stl(w):
    data = _mesh(w).read_bytes()
    _mesh(w).write_bytes(data[: len(data) // 2])


def padded_binary_stl(w):
    _mesh(w).write_bytes(_mesh(w).read_bytes() + b"\0" * 7)


def huge_stl(w):  # a sparse file: the size is refused before anything is read
    n = mesh_read.MAX_MESH_BYTES // 50 + 10
    with open(_mesh(w), "wb") as fh:
        fh.write(b"\0" * 80 + struct.pack("<I", n))
        fh.truncate(84 + 50 * n)


def garbage_stl(w):
    _mesh(w).write_bytes(np.random.default_rng(7).integers(0, 256, 5003, dtype=np.uint8).tobytes())


def empty_stl(w):
    _mesh(w).write_bytes(b"")


def zero_triangle_stl(w):
    _mesh(w).write_bytes(_binary_stl(np.zeros((0, 3, 3))))


def _ascii(tris: np.ndarray) -> str:
    lines = ["solid lane"]
    for t in tris:
        lines += ["facet normal 0 0 1", "outer loop", *(f"vertex {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in t),
                  "endloop", "endfacet"]
    return "\n".join(lines + ["endsolid lane", ""])


def ascii_bad_vertex(w):
    text = _ascii(_lane_triangles(w)).replace("vertex", "vertex 1 2 ; ", 1)
    _mesh(w).write_text(text)


def ascii_truncated(w):
    text = _ascii(_lane_triangles(w))
    _mesh(w).write_text(text[: text.index("\n", len(text) // 2) + 1])  # cut at a line end


def ascii_non_ascii_bytes(w):  # trimesh used to answer "No module named 'charset_normalizer'"
    data = _ascii(_lane_triangles(w)).encode()
    _mesh(w).write_bytes(data[:300] + b"\xff\xfe\xe9" + data[300:])


def ascii_four_vertices(w):
    text = _ascii(_lane_triangles(w)).replace("endloop", "vertex 0 0 0\nendloop", 1)
    _mesh(w).write_text(text)


LANE_URI = f"models/{MODEL}/meshes/lane.stl"  # as the built world.sdf names it (twice)


def garbage_dae(w):
    (_mesh(w).parent / "lane.dae").write_bytes(b"\x00\x01garbage<<<" * 50)
    _sub_in(w / "world.sdf", LANE_URI, LANE_URI.replace(".stl", ".dae"), 2)


def uri_dotdot(w):
    _sub_in(w / "world.sdf", LANE_URI, "../../outside.stl", 2)


def uri_model_dotdot(w):
    _sub_in(w / "world.sdf", LANE_URI, f"model://{MODEL}/../../../../outside.stl", 2)


def uri_absolute(w):
    _sub_in(w / "world.sdf", LANE_URI, f"file://{w.parent.parent / 'outside.stl'}", 2)


def included_model_escape(w):  # the same escape inside an included model file
    _write_model(w / "models" / "deco", "<link name='l'><visual name='v'><geometry><mesh>"
                 "<uri>model://deco/../../../../outside.stl</uri></mesh></geometry></visual></link>")
    _add_to_world(w, "<include><uri>model://deco</uri></include>")


def include_escape(w):
    _add_to_world(w, "<include><uri>model://../..</uri></include>")


def include_relative_escape(w):
    _write_model(w.parent.parent / "elsewhere", "")
    _add_to_world(w, "<include><uri>../../elsewhere</uri></include>")


def symlink_out(w):
    _mesh(w).unlink()
    os.symlink(w.parent.parent / "outside.stl", _mesh(w))


def config_escape(w):
    _sub_in(w / "models" / MODEL / "model.config", ">model.sdf<", ">../../../secret.txt<")
    _add_to_world(w, f"<include><uri>model://{MODEL}</uri><name>again</name></include>")


def doctype_entities(w):
    text = (w / "world.sdf").read_text().replace(
        "<sdf", '<!DOCTYPE sdf [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;">]><sdf', 1)
    (w / "world.sdf").write_text(text)


def huge_sdf(w):
    with open(w / "world.sdf", "a") as fh:
        fh.truncate(sdf_xml.MAX_XML_BYTES + 10)


CASES = {  # name -> (damage, what the one line must say)
    "self_include": (self_include, r"includes itself \(.*loop_a.*loop_a"),
    "mutual_include": (mutual_include, r"includes itself \(.*loop_a.*loop_b.*loop_a"),
    "include_bomb": (include_bomb, r"more than 10,000 models and includes"),
    "deep_nesting": (deep_nesting, r"world\.sdf:\d+: elements nested more than 100 deep"),
    "nesting_40_models": (nesting_40_models, r"world\.sdf:\d+: models and includes nested more than 32 deep"),
    "link_pose_loop": (link_pose_loop, r"relative_to='[ab]'>: expected the model or a sibling link"),
    "huge_coordinate": (huge_coordinate, r"lane\.stl: 'lane_visual' makes the world's meshes span 1e\+06 m"),
    "nan_vertex": (nan_vertex, r"lane\.stl: mesh has non-finite vertex coordinates"),
    "truncated_binary_stl": (truncated_binary_stl, r"lane\.stl: truncated binary STL: its header states \d+ triangles"),
    "padded_binary_stl": (padded_binary_stl, r"lane\.stl: damaged binary STL"),
    "huge_stl": (huge_stl, r"lane\.stl: mesh file of 32\.0 MiB: at most 32 MiB"),
    "garbage_stl": (garbage_stl, r"lane\.stl: (damaged|truncated) binary STL"),
    "empty_stl": (empty_stl, r"lane\.stl: not an STL file \(0 bytes"),
    "zero_triangle_stl": (zero_triangle_stl, r"lane\.stl: mesh has no triangles"),
    "ascii_bad_vertex": (ascii_bad_vertex, r"lane\.stl:4: ASCII STL: expected 'vertex X Y Z'"),
    "ascii_truncated": (ascii_truncated, r"lane\.stl: truncated ASCII STL"),
    "ascii_non_ascii_bytes": (ascii_non_ascii_bytes, r"lane\.stl:\d+: ASCII STL has a non-ASCII byte"),
    "ascii_four_vertices": (ascii_four_vertices, r"lane\.stl:\d+: ASCII STL: a facet needs exactly 3 vertices"),
    "garbage_dae": (garbage_dae, r"lane\.dae: cannot read \.dae mesh"),
    "uri_dotdot": (uri_dotdot, r"world\.sdf:\d+: mesh URI \.\./\.\./outside\.stl: the file .*outside\.stl is outside the world's folder"),
    "uri_model_dotdot": (uri_model_dotdot, r"world\.sdf:\d+: mesh URI model://oval_start/\.\./.*: the file .* is outside"),
    "uri_absolute": (uri_absolute, r"world\.sdf:\d+: mesh URI file:///.*outside\.stl: the file .* is outside"),
    "included_model_escape": (included_model_escape, r"deco/model\.sdf:1: mesh URI model://deco/\.\./.* is outside"),
    "include_escape": (include_escape, r"world\.sdf:\d+: URI model://\.\./\.\.: '\.\./\.\.' is not a model name"),
    "include_relative_escape": (include_relative_escape, r"world\.sdf:\d+: include \.\./\.\./elsewhere: the folder .* is outside"),
    "symlink_out": (symlink_out, r"world\.sdf:\d+: mesh URI models/oval_start/meshes/lane\.stl: the file .* is outside"),
    "config_escape": (config_escape, r"model\.config:\d+: <sdf>\.\./\.\./\.\./secret\.txt</sdf>: expected a file inside"),
    "doctype_entities": (doctype_entities, r"world\.sdf:\d+: <!DOCTYPE> in SDF file"),
    "huge_sdf": (huge_sdf, r"world\.sdf: SDF file of 16\.0 MiB: at most 16 MiB"),
}


def _one_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    assert "Traceback" not in text
    return lines[0]


@pytest.mark.parametrize("case", sorted(CASES))
def test_malformed_world_is_refused_alike_by_validate_and_drive(world, case):
    damage, pattern = CASES[case]
    damage(world)
    t0 = time.process_time()
    with pytest.raises(WorldError, match=pattern) as validate_err:
        validate_path(world, sdf_checker=False)
    with pytest.raises(TrackLoadError, match=pattern) as drive_err:
        load_track(world)
    assert str(validate_err.value) == str(drive_err.value)  # the same one line
    assert "\n" not in str(drive_err.value) and SECRET not in str(drive_err.value)
    assert time.process_time() - t0 < 20  # bounded: a hang would not get here

    runner = CliRunner()
    out_v = runner.invoke(trackgen_main, ["validate", str(world), "--no-sdf-check"])
    out_d = runner.invoke(simrunner_main, ["drive", str(CONTROLLER), "--track", str(world),
                                           "--time-limit", "1"])
    assert (out_v.exit_code, out_d.exit_code) == (2, 2), (out_v.output, out_d.output)
    line_v, line_d = _one_line(out_v.output), _one_line(out_d.output)
    assert line_v == line_d.removeprefix("simrunner: ") == str(drive_err.value)
    assert out_v.exception is None or isinstance(out_v.exception, SystemExit)


def test_check_world_reports_the_escaping_mesh_too(world):
    uri_dotdot(world)
    problems = "\n".join(sdf_read_check(world))
    assert "is outside the world's folder" in problems


def sdf_read_check(world: Path) -> list[str]:
    from worlds.check import check_world

    return check_world(world, use_ign=False)


def test_model_path_allows_reading_outside_on_purpose(world, monkeypatch):
    """The documented way to read meshes elsewhere: put their folder on GAZEBO_MODEL_PATH."""
    uri_dotdot(world)
    with pytest.raises(TrackLoadError, match="outside"):
        load_track(world)
    monkeypatch.setenv("GAZEBO_MODEL_PATH", str(world.parent.parent))
    assert load_track(world).raster.road_mask.any()
    assert not [p for p in validate_path(world, sdf_checker=False) if not p.warning]


def test_track_json_layout_outside_is_not_read_or_echoed(built, tmp_path):
    import json

    out = tmp_path / "oval"
    shutil.copytree(built, out)
    secret = tmp_path.parent / f"{tmp_path.name}-secret.txt"
    secret.write_text(SECRET + "\n")
    for recorded in ("/etc/passwd", str(secret), "../../" + secret.name, "x" * 300):
        doc = json.loads((out / "track.json").read_text())
        doc["layout"] = recorded
        (out / "track.json").write_text(json.dumps(doc))
        result = CliRunner().invoke(trackgen_main, ["validate", str(out), "--no-sdf-check"])
        assert result.exit_code == 0, result.output
        assert "root:" not in result.output and SECRET not in result.output
        assert "the layout was not re-checked" in result.output
        assert load_track(out).raster.road_mask.any()  # drive agrees: the world itself is fine


def test_track_json_layout_that_does_not_parse_is_not_echoed(built, tmp_path):
    import json

    out = tmp_path / "oval"
    shutil.copytree(built, out)
    (tmp_path / "notes.txt").write_text(SECRET + "\n")
    doc = json.loads((out / "track.json").read_text())
    doc["layout"] = "notes.txt"
    (out / "track.json").write_text(json.dumps(doc))
    result = CliRunner().invoke(trackgen_main, ["validate", str(out), "--no-sdf-check"])
    assert result.exit_code == 1 and SECRET not in result.output
    assert "does not load (line 1)" in result.output


def test_the_real_tracks_still_validate_and_load():
    for name in ("nxp_raceway", "nxp_raceway_octagon"):
        folder = ROOT.parent / "shared" / "tracks" / name
        if not folder.is_dir():
            pytest.skip("NXP tracks not found")
        assert not [p for p in validate_path(folder, sdf_checker=False) if not p.warning]
        assert load_track(folder).raster.road_mask.any()


def test_sdf_read_limits_are_documented():
    for name in ("MAX_MODEL_DEPTH", "MAX_MODELS"):
        assert name in sdf_read.__doc__
    for name in ("MAX_MESH_BYTES", "MAX_WORLD_TRIANGLES", "MAX_EXTENT_M"):
        assert name in mesh_read.__doc__


# -- the mesh reader, property-tested ---------------------------------------------------------
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_FINITE = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, width=32)
_TRIS = st.lists(st.lists(st.tuples(_FINITE, _FINITE, _FINITE), min_size=3, max_size=3),
                 min_size=1, max_size=20)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=3000), prefix=st.sampled_from([b"", b"solid x\n", b"solid"]))
def test_any_bytes_read_as_triangles_or_one_world_error(tmp_path, data, prefix):
    path = tmp_path / "m.stl"
    path.write_bytes(prefix + data)
    try:
        tris = mesh_read.read_triangles(path)
    except WorldError as exc:
        assert "\n" not in str(exc) and str(exc).startswith(str(path))
    else:
        assert tris.ndim == 3 and tris.shape[1:] == (3, 3) and len(tris) and np.isfinite(tris).all()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(tris=_TRIS, cut=st.integers(min_value=1, max_value=49))
def test_stl_round_trip_and_every_truncation_refused(tmp_path, tris, cut):
    tris = np.asarray(tris, dtype=np.float32).astype(float)
    binary, ascii_ = tmp_path / "b.stl", tmp_path / "a.stl"
    binary.write_bytes(_binary_stl(tris))
    ascii_.write_text(_ascii(tris))
    np.testing.assert_array_equal(mesh_read.read_triangles(binary), tris)
    np.testing.assert_array_equal(mesh_read.read_triangles(ascii_), tris)
    data = binary.read_bytes()
    binary.write_bytes(data[:-cut])  # any cut inside the last triangle
    with pytest.raises(WorldError, match="truncated binary STL"):
        mesh_read.read_triangles(binary)
    lines = ascii_.read_text().splitlines(keepends=True)
    ascii_.write_text("".join(lines[: max(1, len(lines) - 1 - cut % len(lines))]))
    with pytest.raises(WorldError, match="ASCII STL"):
        mesh_read.read_triangles(ascii_)


def test_track_json_name_cannot_point_the_mesh_check_outside(built, tmp_path):
    import json

    out = tmp_path / "oval"
    shutil.copytree(built, out)
    doc = json.loads((out / "track.json").read_text())
    doc["name"] = "../../.."
    (out / "track.json").write_text(json.dumps(doc))
    result = CliRunner().invoke(trackgen_main, ["validate", str(out), "--no-sdf-check"])
    assert result.exit_code == 1 and "name '../../..': expected the track model's folder name" in result.output


def test_a_compressed_mesh_is_held_to_the_size_limit_of_what_it_holds(tmp_path):
    """Issue 50 (fault injection): a 1.5 kB .stl.bz2 inflated to ~11 GB in validate and drive."""
    import bz2
    import zipfile

    from trackgen.meshes import SlabMesh, stl_bytes
    from worlds.mesh_read import MAX_MESH_BYTES, read_triangles
    from worlds.sdf_xml import WorldError

    tri = SlabMesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    (tmp_path / "ok.stl.bz2").write_bytes(bz2.compress(stl_bytes(tri)))
    assert read_triangles(tmp_path / "ok.stl.bz2").shape == (1, 3, 3)
    bomb = tmp_path / "lane.stl.bz2"
    bomb.write_bytes(bz2.compress(b"\0" * (MAX_MESH_BYTES + 1)))
    assert bomb.stat().st_size < 200
    with pytest.raises(WorldError, match=r"lane.stl.bz2: compressed mesh holds more than 32 MiB"):
        read_triangles(bomb)
    with zipfile.ZipFile(tmp_path / "lane.zip", "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("lane.stl", b"\0" * (MAX_MESH_BYTES + 1))
    with pytest.raises(WorldError, match=r"lane.zip: zip mesh holds 32.0 MiB"):
        read_triangles(tmp_path / "lane.zip")


def _zip_bytes(members: dict[str, bytes], method: int | None = None) -> bytes:
    import io
    import zipfile

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED if method is None else method) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return buf.getvalue()


def test_a_zip_inside_a_compressed_mesh_is_held_to_the_limit_and_named_as_the_world_names_it(tmp_path):
    """lane.zip.bz2: the zip came out of the bz2 within the limit but was then read as it was,
    its members inflated whole (a 1 MB zip held 1 GiB: 3 GB and 10 s in `validate`); a fault
    in what the bz2 holds was named by a temporary file's path."""
    import bz2
    import gzip

    from worlds.mesh_read import MAX_MESH_BYTES, read_triangles

    (tmp_path / "lane.zip.bz2").write_bytes(bz2.compress(_zip_bytes({"lane.stl": b"\0" * (MAX_MESH_BYTES + 1)})))
    with pytest.raises(WorldError, match=r"^\S*/lane\.zip\.bz2: zip mesh holds 32\.0 MiB: at most 32 MiB are read$"):
        read_triangles(tmp_path / "lane.zip.bz2")
    (tmp_path / "lane.stl.gz.bz2").write_bytes(bz2.compress(gzip.compress(b"solid x\nendsolid x\n")))
    with pytest.raises(WorldError, match=r"^\S*/lane\.stl\.gz\.bz2: a mesh compressed twice \(\.gz inside \.bz2\): "
                                         r"expected one compression$"):
        read_triangles(tmp_path / "lane.stl.gz.bz2")
    (tmp_path / "lane.obj.bz2").write_bytes(bz2.compress(b"v 0 0 0\nv 1 0 0\nf 1 2 9\n"))
    with pytest.raises(WorldError, match=r"^\S*/lane\.obj\.bz2: ") as err:
        read_triangles(tmp_path / "lane.obj.bz2")
    assert "nxpcup-mesh-" not in str(err.value)


def test_a_zip_whose_directory_understates_a_member_is_refused_without_inflating_it(tmp_path):
    """A zip's directory can state any size: a member of 128 MiB stated as 1000 bytes passed the
    limit and was inflated whole before its CRC failed (memory up to ~1000 x the zip's size)."""
    import struct
    import tracemalloc
    import zipfile

    from worlds.mesh_read import read_triangles

    data = bytearray(_zip_bytes({"lane.stl": b"\0" * (128 * 2**20)}))
    for sig, at in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):  # local header, directory entry
        i = data.index(sig)
        data[i + at:i + at + 4] = struct.pack("<I", 1000)
    (tmp_path / "lane.zip").write_bytes(bytes(data))
    assert zipfile.ZipFile(tmp_path / "lane.zip").infolist()[0].file_size == 1000
    tracemalloc.start()
    try:
        with pytest.raises(WorldError, match="Bad CRC-32 for file 'lane.stl'") as err:
            read_triangles(tmp_path / "lane.zip")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20, peak  # bytes; it was the whole 128 MiB and more
    assert str(err.value) == f"{tmp_path / 'lane.zip'}: cannot read zip mesh (Bad CRC-32 for file 'lane.stl')"


def test_a_zip_that_understates_a_member_with_a_matching_crc_is_refused_without_inflating_it(tmp_path):
    """The CRC a zip states can be that of the bytes its directory states: zipfile stops
    there and finds the CRC right, so the check passed and the mesh reader then inflated the
    member whole (301 MB traced for a 130 kB zip, ~1000 x its size)."""
    import struct
    import tracemalloc
    import zlib

    from worlds.mesh_read import read_triangles

    data = bytearray(_zip_bytes({"lane.stl": b"\0" * (128 * 2**20)}))
    crc = zlib.crc32(b"\0" * 1000)
    for sig, size_at, crc_at in ((b"PK\x03\x04", 22, 14), (b"PK\x01\x02", 24, 16)):  # local header, directory
        i = data.index(sig)
        data[i + size_at:i + size_at + 4] = struct.pack("<I", 1000)
        data[i + crc_at:i + crc_at + 4] = struct.pack("<I", crc)
    (tmp_path / "lane.zip").write_bytes(bytes(data))
    tracemalloc.start()
    try:
        with pytest.raises(WorldError, match=r"lane\.zip: cannot read zip mesh \(Bad CRC-32 for file 'lane\.stl'\)$"):
            read_triangles(tmp_path / "lane.zip")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20, peak  # bytes


def test_a_zip_member_compressed_otherwise_than_deflate_is_refused(tmp_path):
    """zipfile inflates a bzip2 or lzma member without a bound per read (4 kB of bzip2 can
    hold gigabytes), so a member whose directory understates it could not be checked."""
    import zipfile

    from trackgen.meshes import SlabMesh, stl_bytes
    from worlds.mesh_read import read_triangles

    tri = stl_bytes(SlabMesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]])))
    (tmp_path / "ok.zip").write_bytes(_zip_bytes({"lane.stl": tri}))
    assert read_triangles(tmp_path / "ok.zip").shape == (1, 3, 3)
    (tmp_path / "lane.zip").write_bytes(_zip_bytes({"lane.stl": tri}, zipfile.ZIP_BZIP2))
    with pytest.raises(WorldError, match=r"lane\.zip: zip mesh member 'lane\.stl' is compressed with bzip2: "
                                         r"expected deflate or stored \(zip it again\)$"):
        read_triangles(tmp_path / "lane.zip")
