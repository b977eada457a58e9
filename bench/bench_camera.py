"""Track loading and camera speed (issue 3 sections 1 and 3).

Rows per track (a layout built on the fly, and both NXP tracks if present):
* ``load``: ``load_track`` (world read, meshes rasterised at 5 mm; a layout is parsed,
  chained, checked and painted in memory, no files);
* ``raster``: rasterisation alone (``build_raster`` of the scene's layers);
* ``render``: one full 128 x 128 frame (``Camera.render``), default camera, supersample 1 and 2;
* ``row``: one row (``Camera.render_row``, the Spinner's line-camera path);
* ``noise``: ``add_noise`` on a full frame.
Times are the best of several runs (ms), poses spread around the start.
"""
from __future__ import annotations

import itertools
import tempfile
import time
from pathlib import Path

import numpy as np

from pieces.pose import Pose2
from simrunner.sensors.camera import Camera
from simrunner.track.raster import build_raster, layer_from_visual
from simrunner.track.load import load_track
from vehicle.description import CarDescription

TRACKS = Path(__file__).resolve().parents[2] / "shared" / "tracks"
OVAL = "@name = oval\nSTART_FINISH\nSTRAIGHT\nTURN_LEFT x4\nSTRAIGHT x2\nTURN_LEFT x4\n"


def _best_ms(fn, repeats: int, inner: int = 1) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        best = min(best, (time.perf_counter() - t0) / inner)
    return best * 1e3


def _specs(tmp: Path) -> list[tuple[str, Path]]:
    layout = tmp / "oval.txt"
    layout.write_text(OVAL)
    specs = [("oval (layout)", layout)]
    for name in ("nxp_raceway", "nxp_raceway_octagon"):
        if (TRACKS / name).is_dir():
            specs.append((name, TRACKS / name))
    return specs


def main() -> None:
    from worlds.sdf_read import read_world

    cam_spec = CarDescription().camera
    rng = np.random.default_rng(0)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, spec in _specs(Path(tmp)):
            load_ms = _best_ms(lambda: load_track(spec), 2 if spec.suffix == ".txt" else 3)
            track = load_track(spec)
            if spec.suffix != ".txt":
                scene = read_world(spec)
                raster_ms = _best_ms(lambda: build_raster([layer_from_visual(v) for v in scene.visuals]), 3)
            else:
                raster_ms = float("nan")
            poses = [track.start @ Pose2(rng.uniform(0, 0.5), rng.uniform(-0.1, 0.1), rng.uniform(-0.3, 0.3))
                     for _ in range(50)]
            it = itertools.cycle(poses)
            figures = {}
            for k in (1, 2):
                cam = Camera(cam_spec, track, supersample=k)
                figures[f"render x{k}"] = _best_ms(lambda: cam.render(next(it)), 5, 200)
                figures[f"row x{k}"] = _best_ms(lambda: cam.render_row(next(it), cam_spec.default_row), 5, 500)
            cam = Camera(cam_spec, track)
            img = cam.render(track.start)
            figures["noise"] = _best_ms(lambda: cam.add_noise(img, rng), 5, 200)
            h, w = track.raster.shape
            rows.append((label, f"{w}x{h}", load_ms, raster_ms, figures))
    keys = list(rows[0][4])
    header = f"{'track':<22} {'raster px':>11} {'load ms':>8} {'raster ms':>9} " + " ".join(f"{k:>10}" for k in keys)
    print(header)
    print("-" * len(header))
    for label, size, load_ms, raster_ms, figures in rows:
        print(f"{label:<22} {size:>11} {load_ms:8.1f} {raster_ms:9.1f} "
              + " ".join(f"{figures[k]:10.3f}" for k in keys))
    print("(render/row/noise columns in ms per call; 128x128 default camera, 5 mm raster)")


if __name__ == "__main__":
    main()
