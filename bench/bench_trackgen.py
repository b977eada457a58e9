"""trackgen speed: parse + chain, validate, export, for layouts of 10 to 1000 pieces.

Columns (milliseconds, best of a few runs, warm imports):
* ``chain``: parse the layout text and chain the pieces (``parse_layout`` + ``chain``);
* ``validate``: world footprint unions, meshes and every check (``check_layout`` minus
  the chain: ``track_geometry`` + ``validate_track`` with the STL round-trip mesh check);
* ``export``: writing the output folder (STL, SDF via worlds, track.json, preview.png),
  of which ``preview`` is the matplotlib PNG;
* ``total``: the sum, i.e. what ``trackgen build`` costs after start-up.
Layouts: the thesis figure 8 (22 pieces) and ovals of N pieces (N/2 short straights and N/2
turns of 360/N degrees) -- cost should grow about linearly with N (overlaps use an STRtree).
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

from trackgen.build import Checked, _move_into_place, _write_all
from trackgen.chain import chain
from trackgen.export import track_geometry
from trackgen.layout import parse_layout
from trackgen.validate import errors, validate_track
from trackgen.preview import render_preview
from vehicle.description import CarDescription

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def oval(n_pieces: int) -> str:
    """A closed oval of ``n_pieces`` (>= 8): a START_FINISH and short straights (0.2 m)
    on two sides, two half circles of ``n_pieces // 4`` turns each."""
    t = n_pieces // 4                      # turns per half circle
    m = n_pieces // 2 - t                  # pieces per straight side
    angle = 180.0 / t
    return (f"@name = oval{n_pieces}\nSTART_FINISH length=0.2\n"
            + (f"STRAIGHT_SHORT length=0.2 x{m - 1}\n" if m > 1 else "")
            + f"TURN_LEFT angle={angle!r} x{t}\n"
            + f"STRAIGHT_SHORT length=0.2 x{m}\n"
            + f"TURN_LEFT angle={angle!r} x{t}\n")


def _best(fn, repeat: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3, out


def measure(text: str, repeat: int = 3) -> dict[str, float]:
    car = CarDescription()
    chain_ms, track = _best(lambda: chain(parse_layout(text, path="bench.txt")), repeat)

    def check():  # a fresh Track each run: its world footprints are cached
        fresh = track.__class__(track.layout, track.passes, track.reentries)
        geometry = track_geometry(fresh)
        return geometry, validate_track(fresh, car.min_turn_radius_m, meshes=geometry.meshes)

    validate_ms, (geometry, problems) = _best(check, repeat)
    assert not errors(problems), [str(p) for p in errors(problems)][:3]
    checked = Checked(track, geometry, problems)

    def export():
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp) / ".work"
            work.mkdir()
            _write_all(work, checked, car, True)
            _move_into_place(work, Path(tmp) / "out", force=False)

    export_ms, _ = _best(export, repeat)
    with tempfile.TemporaryDirectory() as tmp:
        preview_ms, _ = _best(lambda: render_preview(track, geometry, Path(tmp) / "p.png"), repeat)
    return {"pieces": len(track.passes), "chain": chain_ms, "validate": validate_ms,
            "export": export_ms, "preview": preview_ms,
            "total": chain_ms + validate_ms + export_ms}


def main() -> None:
    rows = [("thesis_figure8", (EXAMPLES / "thesis_figure8.txt").read_text(), 3)]
    rows += [(f"oval{n}", oval(n), 3 if n < 1000 else 1) for n in (10, 40, 100, 1000)]
    measure(rows[0][1], 1)  # warm the imports (matplotlib, trimesh export)
    print(f"{'layout':<16}{'pieces':>7}{'chain':>9}{'validate':>10}{'export':>9}"
          f"{'(preview)':>11}{'total':>9}   ms")
    for name, text, repeat in rows:
        r = measure(text, repeat)
        print(f"{name:<16}{r['pieces']:>7}{r['chain']:>9.1f}{r['validate']:>10.1f}"
              f"{r['export']:>9.1f}{r['preview']:>11.1f}{r['total']:>9.1f}")


if __name__ == "__main__":
    main()
