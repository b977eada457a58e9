"""``trackgen build``'s output folder (issue 13 item 16: killed builds, --force window),
its preview (item 4) and what the build process loads (item 10)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from trackgen import outdir
from trackgen.build import build
from trackgen.meshes import SlabMesh, stl_bytes, watertight_after_stl
from trackgen.preview import grid_step_m

ROOT = Path(__file__).resolve().parents[1]
OVAL = ROOT / "examples" / "oval_start.txt"


def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


# -- killed builds ---------------------------------------------------------------------------
def test_temp_folders_of_killed_builds_are_removed_by_the_next_build(tmp_path):
    out = tmp_path / "out"
    stale = tmp_path / f".out.trackgen-{dead_pid()}-abcd1234.tmp"
    stale_old = tmp_path / f".out.trackgen-{dead_pid()}-efgh5678.old"
    live = tmp_path / f".out.trackgen-{os.getppid()}-live0000.tmp"    # a running process
    other = tmp_path / ".out.k2j3h4.tmp"                               # not named by us
    unrelated = tmp_path / f".other.trackgen-{dead_pid()}-x.tmp"        # another output
    for d in (stale, stale_old, live, other, unrelated):
        (d / "models").mkdir(parents=True)
    build(OVAL, out, preview=False)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted(["out", live.name, other.name, unrelated.name])


def test_a_build_killed_midway_leaves_a_folder_the_next_build_removes(tmp_path):
    code = ("import os, sys; from pathlib import Path; import trackgen.build as b\n"
            "def die(*a, **k): os._exit(9)\n"
            "b.replace_folder = die\n"
            f"b.build({str(OVAL)!r}, {str(tmp_path / 'out')!r}, preview=False)\n")
    proc = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 9
    (left,) = tmp_path.iterdir()
    assert left.name.startswith(".out.trackgen-") and left.name.endswith(".tmp")
    build(OVAL, tmp_path / "out", preview=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


# -- --force: the output folder always holds a complete build -----------------------------------
def test_exchange_swaps_two_folders_atomically(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    (a / "new.txt").write_text("new")
    (b / "old.txt").write_text("old")
    if not outdir.exchange(a, b):
        pytest.skip("renameat2(RENAME_EXCHANGE) not available here")
    assert (b / "new.txt").is_file() and (a / "old.txt").is_file()


def test_force_replaces_by_exchange_never_renaming_the_old_build_away(tmp_path, monkeypatch):
    out = tmp_path / "out"
    build(OVAL, out, preview=False)
    (out / "marker").write_text("old build")
    if not outdir.exchange(out, out):  # same path: a no-op that tells whether it works here
        pytest.skip("renameat2(RENAME_EXCHANGE) not available here")
    moved = []
    real_replace = os.replace

    def spy(src, dst, *a, **k):
        moved.append(Path(src))
        return real_replace(src, dst, *a, **k)

    monkeypatch.setattr(os, "replace", spy)
    build(OVAL, out, force=True, preview=False)
    assert out not in moved  # the old build was never moved away: no moment without -o
    assert not (out / "marker").exists() and (out / "track.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_force_falls_back_to_two_renames_without_exchange(tmp_path, monkeypatch):
    out = tmp_path / "out"
    build(OVAL, out, preview=False)
    monkeypatch.setattr(outdir, "exchange", lambda a, b: False)
    build(OVAL, out, force=True, preview=False)
    assert (out / "track.json").is_file() and sorted(p.name for p in tmp_path.iterdir()) == ["out"]


# -- meshes without trimesh --------------------------------------------------------------------
def _box() -> SlabMesh:
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    f = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                  [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    return SlabMesh(v, f[:, ::-1].copy())  # outward normals


def test_watertight_check_agrees_with_trimesh():
    trimesh = pytest.importorskip("trimesh")
    box = _box()
    assert watertight_after_stl(box) == (True, 12, 2)
    open_box = SlabMesh(box.vertices, box.faces[:-1])
    flipped = SlabMesh(box.vertices, np.vstack([box.faces[:-1], box.faces[-1:, ::-1]]))
    for mesh in (box, open_box, flipped):
        ours = watertight_after_stl(mesh)[0]
        tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=True)
        assert ours == (tm.is_watertight and tm.is_winding_consistent)
    # float32 collapse: two vertices 1e-9 apart become one (a degenerate face)
    tiny = SlabMesh(np.array([[0, 0, 0], [1e-9, 0, 0], [0, 1, 0.0]]), np.array([[0, 1, 2]]))
    assert watertight_after_stl(tiny)[0] is False


def test_stl_bytes_are_deterministic_and_readable(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    data = stl_bytes(_box())
    assert data == stl_bytes(_box()) and len(data) == 84 + 50 * 12
    (tmp_path / "b.stl").write_bytes(data)
    back = trimesh.load(tmp_path / "b.stl", force="mesh")
    assert back.is_watertight and back.volume == pytest.approx(1.0)


# -- what the build loads (no timing here: bench/bench_trackgen_build.py measures it) --------
def test_trackgen_build_loads_neither_trimesh_nor_scipy_nor_matplotlib(tmp_path):
    code = ("import sys; from trackgen.cli import main\n"
            f"sys.argv = ['trackgen', 'build', {str(OVAL)!r}, '-o', {str(tmp_path / 'o')!r}]\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('trimesh', 'scipy', 'matplotlib') if m in sys.modules))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "[]"
    assert (tmp_path / "o" / "preview.png").stat().st_size > 10_000


# -- preview: scale and legend -------------------------------------------------------------------
@pytest.mark.parametrize("span, step", [(4.9, 1.0), (10.0, 2.0), (0.3, 0.05), (130.0, 20.0),
                                        (1.6, 0.2), (2.0, 0.25)])
def test_grid_step_is_round(span, step):
    assert grid_step_m(span) == pytest.approx(step)


def test_preview_has_legend_grid_and_scale_bar(tmp_path):
    from PIL import Image

    result = build(OVAL, tmp_path / "o")
    image = np.asarray(Image.open(result.preview_path).convert("RGB")).astype(int)
    h, w, _ = image.shape
    assert (w, h) == result.preview_size_px and max(w, h) == 1200
    legend = image[8:120, 8:258]
    assert (legend == [20, 20, 20]).all(axis=-1).mean() > 0.5          # the legend box
    assert (legend == [255, 255, 255]).all(axis=-1).any()                # the lane swatch
    assert (np.abs(legend - [214, 39, 40]).sum(axis=-1) < 30).any()      # the arrow sample
    bar = image[h - 40:h - 28, w - 300:w - 10]
    assert (bar == [230, 230, 230]).all(axis=-1).sum() > 100             # the scale bar
    grid = (np.abs(image - [75, 75, 75]) <= 8).all(axis=-1)
    assert grid.sum() > 1000                                             # grid lines
