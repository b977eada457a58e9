"""``trackgen build`` as a whole process: what a student waits for, start-up included.

Each run is a fresh ``python -c "from trackgen.cli import main; main()" build LAYOUT -o TMP
--force`` (imports, parse, chain, checks, meshes, STL, SDF, track.json, preview.png).
Layouts: ovals of 40 and 400 pieces (``bench_trackgen.oval``) and the thesis figure 8.
Columns: median / min wall time and median CPU time (user + system of the child; less
sensitive to other processes on a shared machine) over ``REPEAT`` runs, in seconds, and
which heavy libraries the process imported (``loads``). Target (issue 13 item 10): 40
pieces <= 1.0 s wall on an idle machine.

``BENCH_TRACKGEN_BASE=/path/to/other/checkout python -m bench trackgen_build`` adds the
same rows for another checkout (e.g. the commit before a change), run interleaved with
this one so both see the same machine load.
"""
from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.bench_trackgen import EXAMPLES, oval

REPO = Path(__file__).resolve().parents[1]
REPEAT = 5
HEAVY = ("scipy", "trimesh", "matplotlib", "PIL", "stl", "manifold3d", "shapely", "numpy")
_MARK = "bench loaded:"
_CODE = ("import atexit, sys; atexit.register(lambda: sys.stderr.write("
         f"'\\n{_MARK}' + ' '.join(m for m in {HEAVY!r} if m in sys.modules) + '\\n')); "
         "from trackgen.cli import main; sys.exit(main())")


def run_once(repo: Path, layout: Path, out: Path) -> tuple[float, float, str]:
    """(wall s, child CPU s, heavy modules loaded) of one build in a fresh process."""
    env = dict(os.environ, PYTHONPATH=str(repo))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", _CODE, "build", str(layout), "-o", str(out),
                           "--force"], cwd=repo, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"trackgen build failed: {proc.stderr.strip()[-500:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    loads = next((line.split(":", 1)[1].strip() for line in proc.stderr.splitlines()
                  if line.startswith(_MARK)), "")
    return wall, cpu, loads


def main() -> None:
    base = os.environ.get("BENCH_TRACKGEN_BASE")
    repos = [("this", REPO)] + ([("base", Path(base))] if base else [])
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        layouts = [("oval40", tmp / "oval40.txt"), ("oval400", tmp / "oval400.txt"),
                   ("thesis_figure8", EXAMPLES / "thesis_figure8.txt")]
        (tmp / "oval40.txt").write_text(oval(40))
        (tmp / "oval400.txt").write_text(oval(400))
        for label, repo in repos:  # warm the OS file cache
            run_once(repo, layouts[0][1], tmp / f"warm_{label}")
        times: dict[tuple[str, str], list[tuple[float, float, str]]] = {}
        for _ in range(REPEAT):
            for name, layout in layouts:
                for label, repo in repos:
                    times.setdefault((label, name), []).append(
                        run_once(repo, layout, tmp / f"out_{label}_{name}"))
    print(f"{'checkout':<9}{'layout':<16}{'wall med':>9}{'min':>7}{'cpu med':>9}   loads")
    for (label, name), runs in times.items():
        walls, cpus = [r[0] for r in runs], [r[1] for r in runs]
        print(f"{label:<9}{name:<16}{statistics.median(walls):>9.2f}{min(walls):>7.2f}"
              f"{statistics.median(cpus):>9.2f}   {runs[-1][2]}")
    print(f"load average while measuring: {os.getloadavg()[0]:.1f} "
          f"({os.cpu_count()} CPUs); REPEAT = {REPEAT}")


if __name__ == "__main__":
    main()
