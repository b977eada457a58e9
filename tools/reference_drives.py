"""The reference drives whose CSV bytes must not move unless a change means to move them.

    python tools/reference_drives.py OUT_DIR            (with the environment's interpreter)
    python tools/reference_drives.py --compare DIR_A DIR_B

Drives ``examples/line_follower.py`` for one lap (seed 0) on the bundled default track and,
when ``../shared/tracks`` is beside the checkout, on ``nxp_raceway`` and
``nxp_raceway_octagon``; the default track again with the ideal camera (``camera.model =
"ideal"``: the images of earlier versions); and one run whose controller takes the whole 2-D
camera frame with noise and logs a digest of its pixels, with each camera (the full-frame
paths, which the line follower does not use). Writes ``OUT_DIR/<name>.csv`` and ``OUT_DIR/digests.txt``
(``sha256  name``), and the installed versions of the libraries whose arithmetic reaches the
bytes (``OUT_DIR/versions.txt``). ``--compare`` prints which libraries moved and which drives
differ (and from which row), exit status 1 when any does. ``make test-latest`` runs both.
"""
from __future__ import annotations

import hashlib
import sys
from importlib import metadata
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED_TRACKS = REPO.parent / "shared" / "tracks"
LIBRARIES = ("numpy", "opencv-python-headless", "dartpy", "shapely", "manifold3d", "trimesh",
             "numba", "scipy")


def full_frame_controller(s) -> None:
    """Straight ahead at 1 m/s for 2 s, logging a digest of each noisy 2-D frame."""
    import zlib

    s.set_speed_and_servo(1.0, 0.0)
    while s.get_time() < 2.0:
        img = s.get_image()
        s.add_data([f"crc:{zlib.crc32(img.tobytes()):08x}"])


def reference_runs() -> list[tuple[str, object, object, object]]:
    """``(name, controller, track, car)`` of every reference drive this checkout can run."""
    import dataclasses

    from vehicle.description import CarDescription

    base = CarDescription()
    ideal = base.replace(camera=dataclasses.replace(base.camera, model="ideal"))
    follower = REPO / "examples" / "line_follower.py"
    runs = [("default", follower, None, None), ("full_frame", full_frame_controller, None, None),
            ("ideal_default", follower, None, ideal), ("ideal_full_frame", full_frame_controller, None, ideal)]
    for name in ("nxp_raceway", "nxp_raceway_octagon"):
        if (SHARED_TRACKS / name).is_dir():
            runs.append((name, follower, SHARED_TRACKS / name, None))
    return runs


def main(out_dir: str) -> int:
    from simrunner.run.runner import drive

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lines = []
    for name, controller, track, car in reference_runs():
        csv = out / f"{name}.csv"
        # off_track_wheels=1: the judging the digests were first recorded with (any wheel
        # off ends the run; the full-frame drives leave the track)
        drive(controller, track=track, car=car, laps=1, seed=0, csv=csv, off_track_wheels=1)
        lines.append(f"{hashlib.sha256(csv.read_bytes()).hexdigest()}  {name}")
    (out / "digests.txt").write_text("\n".join(lines) + "\n")
    versions = [f"python=={sys.version.split()[0]}"]
    versions += [f"{lib}=={metadata.version(lib)}" for lib in LIBRARIES]
    (out / "versions.txt").write_text("\n".join(versions) + "\n")
    return 0


def _read_pairs(path: Path, sep: str) -> dict[str, str]:
    pairs = (line.split(sep, 1) for line in path.read_text().splitlines() if line.strip())
    return {k.strip(): v.strip() for k, v in pairs} if sep == "==" else \
        {v.strip(): k.strip() for k, v in pairs}


def _first_difference(a: Path, b: Path) -> str:
    rows_a, rows_b = a.read_text().splitlines(), b.read_text().splitlines()
    for i, (ra, rb) in enumerate(zip(rows_a, rows_b)):
        if ra != rb:
            return f"first differs at line {i + 1}:\n      {ra[:160]}\n      {rb[:160]}"
    return f"{len(rows_a)} lines against {len(rows_b)}"


def compare(dir_a: str, dir_b: str) -> int:
    """Print the library versions that differ and the drives whose CSV bytes differ."""
    a, b = Path(dir_a), Path(dir_b)
    va, vb = _read_pairs(a / "versions.txt", "=="), _read_pairs(b / "versions.txt", "==")
    for lib in sorted(set(va) | set(vb)):
        if va.get(lib) != vb.get(lib):
            print(f"version  {lib}: {va.get(lib)} -> {vb.get(lib)}")
    da, db = _read_pairs(a / "digests.txt", "  "), _read_pairs(b / "digests.txt", "  ")
    moved = 0
    for name in sorted(set(da) | set(db)):
        if name not in da or name not in db:
            print(f"drive    {name}: only in {a if name in da else b}")
        elif da[name] == db[name]:
            print(f"drive    {name}: byte-identical")
        else:
            moved += 1
            print(f"drive    {name}: DIFFERS, {_first_difference(a / f'{name}.csv', b / f'{name}.csv')}")
    return 1 if moved else 0


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--compare":
        sys.exit(compare(sys.argv[2], sys.argv[3]))
    if len(sys.argv) != 2 or sys.argv[1].startswith("-"):
        sys.exit("usage: python tools/reference_drives.py OUT_DIR | --compare DIR_A DIR_B")
    sys.exit(main(sys.argv[1]))
