"""World reading: NXP's tracks through ``trackgen validate`` and ``simrunner``'s track
loading, and what refusing a malformed world costs (issue 13, items 3 and 14).

Columns: milliseconds (best of 3, warm imports) and the peak of Python/numpy allocations
(tracemalloc, MiB) of one call.
* ``validate``: ``trackgen.world_check.validate_world`` without ``ign sdf -k`` (read the
  world, road footprint, centreline trace, width and radius checks), with the measured
  road width, tightest radius and traced loop length;
* ``load``: ``simrunner.track.load_track`` (read the world, raster);
* refusals, each made in a temporary folder from the NXP raceway: a vertex at 1e6 m (the
  raster used to ask for 35 PiB), a mesh file just over the size limit (a sparse file: the
  size is read, not the file), 5,000 nested ``<model>``s, two models including each other,
  2**20 includes through 20 models (each including the next twice), a truncated binary STL.
"""
from __future__ import annotations

import shutil
import struct
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

TRACKS = Path(__file__).resolve().parents[2] / "shared" / "tracks"


def _measure(fn, repeat: int = 3):
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        try:
            out = fn()
        except Exception as exc:  # noqa: BLE001 - the refusals are the point
            out = exc
        best = min(best, time.perf_counter() - t0)
    tracemalloc.start()
    try:
        fn()
    except Exception:  # noqa: BLE001
        pass
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return best * 1e3, peak, out


def _damages(root: Path) -> dict:
    from worlds import mesh_read

    mesh = root / "meshes" / "CourseInside.stl"

    def far_vertex():
        tris = mesh_read.read_triangles(mesh).astype("<f4")
        tris[0, 0, :2] = 1e6
        data = mesh.read_bytes()
        rec = np.frombuffer(data, dtype=mesh_read._STL_RECORD, offset=84).copy()
        rec["vertices"] = tris
        mesh.write_bytes(data[:84] + rec.tobytes())

    def huge_file():
        n = mesh_read.MAX_MESH_BYTES // 50 + 10
        with open(mesh, "wb") as fh:
            fh.write(b"\0" * 80 + struct.pack("<I", n))
            fh.truncate(84 + 50 * n)

    def deep():
        w = root / "nxp_raceway.world"
        w.write_text(w.read_text().replace("</world>", "<model name='n'>" * 5000 + "</model>" * 5000 + "</world>"))

    def _model(name, body):
        d = root / "models" / name
        d.mkdir(parents=True, exist_ok=True)
        (d / "model.config").write_text(f"<model><name>{name}</name><sdf version='1.6'>model.sdf</sdf></model>")
        (d / "model.sdf").write_text(f"<sdf version='1.6'><model name='{name}'>{body}</model></sdf>")

    def _include(name):
        w = root / "nxp_raceway.world"
        w.write_text(w.read_text().replace("</world>", f"<include><uri>model://{name}</uri></include></world>"))

    def mutual():
        _model("a", "<include><uri>model://b</uri></include>")
        _model("b", "<include><uri>model://a</uri></include>")
        _include("a")

    def bomb():
        for i in range(20):
            _model(f"m{i}", f"<include><uri>model://m{i + 1}</uri></include>" * 2 if i < 19 else "")
        _include("m0")

    def truncated():
        mesh.write_bytes(mesh.read_bytes()[:-1000])

    return {"vertex at 1e6 m": far_vertex, "mesh over the size limit": huge_file,
            "5,000 nested models": deep, "mutual include": mutual, "2**20 includes": bomb,
            "truncated binary STL": truncated}


def main() -> None:
    from simrunner.track import load_track
    from trackgen.world_check import tightest_radius, trace_centreline, validate_world

    print(f"{'world':<34}{'validate ms':>12}{'MiB':>7}{'load ms':>10}{'MiB':>7}  result")
    for name in ("nxp_raceway", "nxp_raceway_octagon"):
        folder = TRACKS / name
        v_ms, v_mb, problems = _measure(lambda: validate_world(folder, sdf_checker=False))
        l_ms, l_mb, _ = _measure(lambda: load_track(folder))
        from trackgen.world_check import read_world_road

        world = read_world_road(folder)
        trace = trace_centreline(world.road, world.start)
        radius, _ = tightest_radius(trace.points, trace.closed)
        print(f"{name:<34}{v_ms:>12.0f}{v_mb:>7.1f}{l_ms:>10.0f}{l_mb:>7.1f}  road "
              f"{np.nanmedian(trace.widths):.3f} m (narrowest {np.nanmin(trace.widths):.3f}), "
              f"tightest radius {radius:.3f} m, loop {trace.length_m:.2f} m "
              f"({'closed' if trace.closed else 'open'}), {len(problems)} problem(s)")
    with tempfile.TemporaryDirectory() as tmp:
        for what, damage in _damages(Path(tmp) / "probe").items():
            root = Path(tmp) / what.replace(" ", "_").replace("*", "") / "nxp_raceway"
            shutil.copytree(TRACKS / "nxp_raceway", root)
            _damages(root)[what]()
            v_ms, v_mb, err = _measure(lambda: validate_world(root, sdf_checker=False))
            l_ms, l_mb, _ = _measure(lambda: load_track(root))
            line = str(err).replace(str(root), "...")
            print(f"{what:<34}{v_ms:>12.1f}{v_mb:>7.1f}{l_ms:>10.1f}{l_mb:>7.1f}  {type(err).__name__}: "
                  f"{line[:90]}")


if __name__ == "__main__":
    main()
