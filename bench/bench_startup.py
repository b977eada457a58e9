"""Start-up time of the command-line tools: how long a student waits to try a change.

Each command runs in a fresh subprocess (the installed console scripts' entry points, so
nothing is imported or cached in the bench process); columns are the median / min / max
wall time in seconds over ``REPEAT`` runs. Commands:

* ``simrunner --help`` and ``trackgen --help``: imports only;
* ``simrunner drive examples/line_follower.py --laps 1``: the default track (the bundled
  figure 8 layout, made in memory every run: parsed, chained, checked and rasterised, no
  files and no cache), after one untimed run (numba's kernel cache and the OS file cache
  warm: what a student iterating on a controller sees) -- the simulation itself is well
  under half a second;
* the same with ``--track`` the real NXP raceway (``shared/tracks/nxp_raceway``, a Gazebo
  world read through ``worlds``; skipped when that folder is absent);
* ``trackgen build examples/oval_start.txt -o TMP --force``.

Then the issue-13 target: ``simrunner drive line_follower --time-limit 60`` (60 simulated
seconds on the default track, ``REPEAT`` fresh processes after one warm-up): the whole
process (target >= 35x real time, i.e. <= 1.71 s) and its start-up = whole process minus
the run loop's own wall time from ``--summary`` (target <= 0.6 s); also the CPU seconds
(user + system) of the processes, which a busy machine inflates less than wall time, and
the load average before and after (the targets are for an idle machine).

The second table: ``python -c "import MODULE"`` wall time for the main modules, and the bare
interpreter (``python -c pass``) for reference. Column ``loads``: which of the heavy
libraries (:data:`HEAVY`) the process had imported when it exited -- what to look at when a
row gets slower. Times depend on the machine's load: compare runs made under the same
conditions.
"""
from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
TRACKS = REPO.parent / "shared" / "tracks"
REPEAT = 5
SIXTY_S = 60.0
TARGET_FACTOR, TARGET_STARTUP_S = 35.0, 0.6
MODULES = ("pieces", "pieces.pose", "worlds", "trackgen", "trackgen.cli", "simrunner",
           "simrunner.cli", "simrunner.run.runner", "simrunner.sensors.camera")
HEAVY = ("scipy", "trimesh", "manifold3d", "shapely", "matplotlib", "cv2", "dartpy", "numba")
_MARK = "bench_startup loaded:"
# Python run in each fresh process before the code: reports HEAVY on exit (stderr).
_REPORT = ("import atexit, sys; atexit.register(lambda: sys.stderr.write("
           f"'\\n{_MARK}' + ' '.join(m for m in {HEAVY!r} if m in sys.modules) + '\\n')); ")


def _python(code: str) -> list[str]:
    return [sys.executable, "-c", _REPORT + code]


def _entry(tool: str) -> list[str]:
    """The console script ``tool`` as the installed entry point runs it."""
    return _python(f"from {tool}.cli import main; sys.exit(main())")


def commands(tmp: Path) -> list[tuple[str, list[str], dict[str, str], bool]]:
    """(label, argv, environment overrides, warm-up run first) of every timed command; argv
    runs from the repository root; ``tmp`` holds the outputs."""
    simrunner, trackgen = _entry("simrunner"), _entry("trackgen")
    drive = [*simrunner, "drive", "examples/line_follower.py", "--laps", "1"]
    rows = [("simrunner --help", [*simrunner, "--help"], {}, False),
            ("simrunner drive line_follower --laps 1", drive, {}, True)]
    if (TRACKS / "nxp_raceway").is_dir():
        rows.append(("  ... --track nxp_raceway", [*drive, "--track", str(TRACKS / "nxp_raceway")],
                     {}, True))
    rows += [("trackgen --help", [*trackgen, "--help"], {}, False),
             ("trackgen build oval_start.txt", [*trackgen, "build", "examples/oval_start.txt",
                                                "-o", str(tmp / "oval"), "--force"], {}, False)]
    return rows


def wall_times_s(argv: list[str], repeat: int = REPEAT, env: dict[str, str] | None = None,
                 warm: bool = False) -> tuple[list[float], str]:
    """Wall times in seconds of ``repeat`` fresh runs of ``argv`` (each must exit 0; with
    ``warm`` after one untimed run) and the HEAVY modules the last run had loaded
    (space-separated). ``env`` overrides environment variables."""
    times, loaded = [], ""
    environ = {**os.environ, **(env or {})}
    for i in range(repeat + int(warm)):
        t0 = time.perf_counter()
        done = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, env=environ)
        elapsed_s = time.perf_counter() - t0
        if done.returncode != 0:
            raise RuntimeError(f"{' '.join(argv)} exited {done.returncode}: "
                               f"{done.stderr.strip()[-300:]}")
        if warm and i == 0:
            continue
        times.append(elapsed_s)
        marks = [line for line in done.stderr.splitlines() if line.startswith(_MARK)]
        loaded = marks[-1][len(_MARK):].strip() if marks else ""
    return times, loaded


def sixty_seconds(tmp: Path, repeat: int = REPEAT) -> dict[str, list[float]]:
    """Whole-process wall and CPU seconds, loop wall seconds and start-up seconds of
    ``repeat`` fresh ``drive --time-limit 60`` processes (after one warm-up run)."""
    import json
    import resource

    summary = tmp / "sixty.json"
    argv = [*_entry("simrunner"), "drive", "examples/line_follower.py", "--laps", "1000",
            "--time-limit", f"{SIXTY_S:g}", "--summary", str(summary)]
    out: dict[str, list[float]] = {"wall": [], "cpu": [], "loop": [], "startup": []}
    for i in range(repeat + 1):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        done = subprocess.run(argv, cwd=REPO, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        data = json.loads(summary.read_text())
        if data["outcome"] != "timeout" or abs(data["sim_time_s"] - SIXTY_S) > 0.05:
            raise RuntimeError(f"unexpected run: {data['outcome']} {done.stderr[-300:]}")
        if i == 0:
            continue
        out["wall"].append(wall)
        out["cpu"].append((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime))
        out["loop"].append(data["wall_time_s"])
        out["startup"].append(wall - data["wall_time_s"])
    return out


def _sixty_report(m: dict[str, list[float]]) -> dict[str, float]:
    """Print the 60-s table; returns its medians."""
    med = {k: statistics.median(v) for k, v in m.items()}
    factor = SIXTY_S / med["wall"]
    print(f"{'60 simulated s, default track':<40} {'median':>7} {'min':>7} {'max':>7}")
    for key, label in (("wall", "whole process (wall s)"), ("cpu", "whole process (CPU s)"),
                       ("loop", "run loop (wall s)"), ("startup", "start-up = whole - loop (s)")):
        print(f"{label:<40} {med[key]:7.2f} {min(m[key]):7.2f} {max(m[key]):7.2f}")
    print(f"real-time factor of the whole process: {factor:.1f}x (target >= {TARGET_FACTOR:g}x: "
          f"{'met' if factor >= TARGET_FACTOR else 'not met'}); start-up {med['startup']:.2f} s "
          f"(target <= {TARGET_STARTUP_S} s: {'met' if med['startup'] <= TARGET_STARTUP_S else 'not met'})")
    return med


def _row(label: str, measured: tuple[list[float], str], saved: list | None = None) -> str:
    """A table row; with ``saved``, its figures are appended there too."""
    times, loaded = measured
    if saved is not None:
        saved.append({"command": label.strip(), "median_s": round(statistics.median(times), 3),
                      "min_s": round(min(times), 3), "max_s": round(max(times), 3)})
    return (f"{label:<40} {statistics.median(times):7.2f} {min(times):7.2f} {max(times):7.2f}  "
            f"{loaded or '-'}")


def main() -> None:
    header = f"{'':<40} {'median':>7} {'min':>7} {'max':>7}  loads"
    load0 = os.getloadavg()[0]
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        sixty = _sixty_report(sixty_seconds(Path(tmp)))
        print(f"load average {load0:.1f} -> {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        print()
        print(f"{'command (wall s, fresh process)':<40}" + header[40:])
        for label, argv, env, warm in commands(Path(tmp)):
            print(_row(label, wall_times_s(argv, env=env, warm=warm), rows))
    if not (TRACKS / "nxp_raceway").is_dir():
        print(f"(nxp_raceway row skipped: no {TRACKS / 'nxp_raceway'})")
    print()
    print(f"{'import (wall s, fresh process)':<40}" + header[40:])
    print(_row("(bare interpreter)", wall_times_s([sys.executable, "-c", "pass"])))
    for module in MODULES:
        print(_row(f"import {module}", wall_times_s(_python(f"import {module}"))))
    from bench.record import save

    save("startup", {"repeat": REPEAT, "sim_s": SIXTY_S, "target_factor": TARGET_FACTOR,
                     "target_startup_s": TARGET_STARTUP_S, "load_before": round(load0, 1),
                     "sixty": {k: round(v, 3) for k, v in sixty.items()}, "commands": rows})


if __name__ == "__main__":
    main()
