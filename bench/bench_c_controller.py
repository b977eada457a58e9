"""C controllers (issue 11): closed-loop speed of examples/line_follower.c against
examples/line_follower.py in the same process, and the start-up a student sees.

Closed loop: one lap of the default track, video off, the controllers interleaved
``REPEATS`` times, best (and median) of each kept, with the load average, and the median
of the per-round ratio Python / C with its bootstrap interval. ``wall`` is the
run's wall time (``RunResult``; the C controller's library is opened before the run - or,
``--isolate``, its process started with the library loaded - like the Python file is
compiled before it); for ``--isolate`` ``CPU`` adds the child process's CPU time during the
run (``RUSAGE_CHILDREN`` less its start-up, read from ``/proc/PID/schedstat`` before the
run) to the simulator's. The two laps log the same numbers
(same arithmetic), so the runs do the same physics. Target: real-time factor of C >= that of
Python.

Split (``split``): the same laps again with ``Spinner.get_image`` and
``Spinner.set_speed_and_servo`` timed (the same wrapper for both controllers). Both
controllers make the same calls with the same arguments in the same order (their logs are
equal), so the time inside them is the same work; what differs is the time *outside* them:
the controller's own code, its transport (a C controller's switch and request parsing) and
the run's set-up and tear-down. Per lap, that outside time is a few milliseconds of a
~130 ms lap, far below the noise of whole-lap walls; its paired difference (Python - C, same
round) with a bootstrap interval says which controller costs the run more, and the RTF ratio
it implies (the mean inside time + each one's outside time) is the low-noise form of the
closed-loop ratio.

Start-up (each a fresh ``simrunner drive ... --laps 1`` process, median of ``REPEAT``):

* ``python``: ``examples/line_follower.py`` (after one untimed run: caches warm);
* ``C, new``: a copy of ``line_follower.c`` with a changed comment (a new build: compile
  + load + 1 lap; the host program already built) - target < 3 s;
* ``C, new + host``: the same with an empty cache (the host program is built too, once per
  installation);
* ``C, cached``: the same source again - target < python + 0.2 s.

Times on a shared machine depend on its load: compare rows of one run.
"""
from __future__ import annotations

import dataclasses
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from simrunner.run.runner import drive, resolve_track
from vehicle.description import load_car

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "examples"
REPEATS = 24
REPEAT = 3
FIRST_RUN_TARGET_S = 3.0
CACHED_MARGIN_S = 0.2


def _children_cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _started_cpu_s(pid: int) -> float:
    """CPU time of a started process so far (``/proc/PID/schedstat``; 0 where missing)."""
    try:
        return int(Path(f"/proc/{pid}/schedstat").read_text().split()[0]) * 1e-9
    except (OSError, ValueError, IndexError):
        return 0.0


def closed_loop() -> dict:
    """The closed-loop laps (docstring); returns the figures it printed."""
    from simrunner.run.native import build_program, load_native

    car = load_car(None)
    track, _ = resolve_track(None, car)
    names = ("line_follower.py", "line_follower.c", "c --isolate")
    rows = {name: [] for name in names}  # (CPU s, wall s) per lap
    sim_s = {}
    program = build_program([EXAMPLES / "line_follower.c"])  # built (cached) outside the timing
    drive(program, track=track, laps=1)
    load0 = os.getloadavg()[0]
    for _ in range(REPEATS):
        for name in names:
            child0, start_cpu = _children_cpu_s(), 0.0
            if name.endswith(".c"):  # in-process: its library opened before the run, like
                r = drive(load_native(program), track=track, laps=1)  # the .py is compiled
            elif name == "c --isolate":  # a child process, started with its library loaded
                ctrl = load_native(dataclasses.replace(program, isolate=True))
                start_cpu = _started_cpu_s(ctrl._ready.proc.pid)
                r = drive(ctrl, track=track, laps=1)
            else:
                r = drive(EXAMPLES / name, track=track, laps=1)
            cpu = r.cpu_time_s + _children_cpu_s() - child0 - start_cpu
            rows[name].append((cpu, r.wall_time_s))
            sim_s[name] = r.sim_time_s
    load1 = os.getloadavg()[0]
    print(f"closed loop, one lap of the default track, {REPEATS} laps each (interleaved), "
          f"load average {load0:.2f} -> {load1:.2f}:")
    print(f"  {'controller':<18} {'sim s':>6} {'wall s':>7} {'CPU s':>6} {'RTF wall':>9} {'RTF CPU':>8}"
          f"   (best; median)")
    best = {}
    for name in names:
        cpu = [c for c, _ in rows[name]]
        wall = [w for _, w in rows[name]]
        best[name] = (min(cpu), min(wall))
        print(f"  {name:<18} {sim_s[name]:6.2f} {min(wall):7.3f} {min(cpu):6.3f} "
              f"{sim_s[name] / min(wall):9.1f} {sim_s[name] / min(cpu):8.1f}   "
              f"(median: {sim_s[name] / statistics.median(wall):.1f}, "
              f"{sim_s[name] / statistics.median(cpu):.1f})")
    c, py = best["line_follower.c"], best["line_follower.py"]
    ratio = (sim_s["line_follower.c"] / c[1]) / (sim_s["line_follower.py"] / py[1])
    ratio_cpu = (sim_s["line_follower.c"] / c[0]) / (sim_s["line_follower.py"] / py[0])
    med = {name: statistics.median(w for _, w in rows[name]) for name in names}
    ratio_med = med["line_follower.py"] / med["line_follower.c"]  # same simulated time
    lo, mid, hi = paired_ratio_ci([w for _, w in rows["line_follower.py"]],
                                  [w for _, w in rows["line_follower.c"]])
    iso = best["c --isolate"]
    ratio_iso = (sim_s["c --isolate"] / iso[1]) / (sim_s["line_follower.py"] / py[1])
    print(f"  RTF C / Python: wall {ratio:.3f} (medians {ratio_med:.3f}), CPU {ratio_cpu:.3f}  "
          f"(target >= 1.0: {'met' if ratio >= 1.0 else 'NOT met'}); "
          f"--isolate / Python: wall {ratio_iso:.3f} (CPU counts the C child's run, not its start)")
    print(f"  paired laps (Python wall / C wall, same round): median {mid:.3f}, 95 % bootstrap "
          f"interval of the median {lo:.3f}-{hi:.3f}")
    return {"repeats": REPEATS, "sim_s": round(sim_s["line_follower.py"], 2),
            "laps": [{"controller": name, "rtf_wall": round(sim_s[name] / best[name][1], 1),
                      "rtf_wall_median": round(sim_s[name] / med[name], 1)} for name in names],
            "ratio": round(ratio, 3), "ratio_median": round(ratio_med, 3),
            "paired": [round(lo, 3), round(mid, 3), round(hi, 3)],
            "ratio_isolate": round(ratio_iso, 3)}


def split() -> dict:
    """The laps split inside / outside the Spinner calls (docstring); returns the figures."""
    from simrunner.run import spinner as sp
    from simrunner.run.native import build_program, load_native

    car = load_car(None)
    track, _ = resolve_track(None, car)
    program = build_program([EXAMPLES / "line_follower.c"])
    inside = [0.0]
    clock = time.perf_counter
    get_image, set_both = sp.Spinner.get_image, sp.Spinner.set_speed_and_servo

    def timed_get_image(self, line=-1, add_noise=True):
        t0 = clock()
        try:
            return get_image(self, line, add_noise)
        finally:
            inside[0] += clock() - t0

    def timed_set_both(self, speed, angle):
        t0 = clock()
        try:
            set_both(self, speed, angle)
        finally:
            inside[0] += clock() - t0

    rows = {"py": [], "c": []}  # (inside s, outside s) per lap
    sp.Spinner.get_image, sp.Spinner.set_speed_and_servo = timed_get_image, timed_set_both
    try:
        drive(program, track=track, laps=1)
        for _ in range(REPEATS):
            for name in rows:
                ctrl = load_native(program) if name == "c" else EXAMPLES / "line_follower.py"
                inside[0] = 0.0
                r = drive(ctrl, track=track, laps=1)
                rows[name].append((inside[0], r.wall_time_s - inside[0]))
    finally:
        sp.Spinner.get_image, sp.Spinner.set_speed_and_servo = get_image, set_both
    import numpy as np

    out_py = np.array([o for _, o in rows["py"]])
    out_c = np.array([o for _, o in rows["c"]])
    diff = out_py - out_c
    boots = np.median(np.random.default_rng(0).choice(diff, (2000, diff.size)), axis=1)
    lo, hi = np.percentile(boots, [2.5, 97.5])
    inside_s = statistics.mean(i for rs in rows.values() for i, _ in rs)
    ratio = (inside_s + float(np.median(out_py))) / (inside_s + float(np.median(out_c)))
    print(f"split of the lap ({REPEATS} rounds): inside the Spinner calls {inside_s * 1e3:.1f} ms "
          f"(mean of both); outside them, median: Python {np.median(out_py) * 1e3:.2f} ms, "
          f"C {np.median(out_c) * 1e3:.2f} ms")
    in_diff = np.array([i for i, _ in rows["py"]]) - np.array([i for i, _ in rows["c"]])
    print(f"  Python - C outside, same round: median {np.median(diff) * 1e3:+.3f} ms, 95 % "
          f"bootstrap interval {lo * 1e3:+.3f} to {hi * 1e3:+.3f} ms; implied RTF C / Python "
          f"{ratio:.4f} (target >= 1.0: {'met' if lo > 0 else 'not shown' if hi > 0 else 'NOT met'})")
    print(f"  (inside, Python - C, same round: median {np.median(in_diff) * 1e3:+.2f} ms, "
          f"spread {np.percentile(in_diff, 10) * 1e3:+.2f} to {np.percentile(in_diff, 90) * 1e3:+.2f} ms "
          f"(10-90 %): the same work, its noise is the whole-lap ratio's)")
    return {"inside_ms": round(inside_s * 1e3, 2), "outside_py_ms": round(float(np.median(out_py)) * 1e3, 3),
            "outside_c_ms": round(float(np.median(out_c)) * 1e3, 3),
            "outside_diff_ms": [round(float(x) * 1e3, 3) for x in (lo, np.median(diff), hi)],
            "implied_ratio": round(ratio, 4)}


def paired_ratio_ci(py_wall_s: list[float], c_wall_s: list[float], n_boot: int = 2000,
                    seed: int = 0) -> tuple[float, float, float]:
    """(2.5 %, median, 97.5 %) of the median of the per-round ratios Python wall / C wall
    (the laps of one round ran back to back: their ratio cancels the machine's slow drifts),
    the interval by a percentile bootstrap over the rounds."""
    import numpy as np

    r = np.asarray(py_wall_s) / np.asarray(c_wall_s)
    boots = np.median(np.random.default_rng(seed).choice(r, (n_boot, r.size)), axis=1)
    lo, hi = np.percentile(boots, [2.5, 97.5])
    return float(lo), float(np.median(r)), float(hi)


def _wall_s(argv: list[str], env: dict[str, str], repeat: int, before=None) -> list[float]:
    out = []
    for _ in range(repeat):
        if before is not None:
            before()
        t0 = time.perf_counter()
        done = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, env=env)
        out.append(time.perf_counter() - t0)
        if done.returncode != 0:
            raise RuntimeError(f"{' '.join(argv)} failed:\n{done.stdout}{done.stderr}")
    return out


def start_up() -> dict:
    """The start-up of fresh processes (docstring); returns the figures it printed."""
    cli = [sys.executable, "-c", "import sys; from simrunner.cli import main; sys.exit(main())",
           "drive"]
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "SIMRUNNER_CACHE_DIR": str(Path(tmp) / "cache"),
               "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
        src = Path(tmp) / "follower.c"
        base = (EXAMPLES / "line_follower.c").read_text()
        counter = iter(range(10**6))
        lane_h = (EXAMPLES / "lane_tracker.h").read_text()
        (Path(tmp) / "lane_tracker.h").write_text(lane_h)

        def new_source() -> None:  # a new controller: different content, not in the cache
            src.write_text(base + f"/* variant {next(counter)} */\n")

        def empty_cache() -> None:
            new_source()
            subprocess.run(["rm", "-rf", env["SIMRUNNER_CACHE_DIR"]], check=True)

        py = [*cli, "examples/line_follower.py", "--laps", "1"]
        c = [*cli, str(src), "--laps", "1"]
        _wall_s(py, env, 1)  # warm caches (numba, OS file cache)
        rows = [("python line_follower.py", _wall_s(py, env, REPEAT)),
                ("C, new + host", _wall_s(c, env, REPEAT, empty_cache)),
                ("C, new", _wall_s(c, env, REPEAT, new_source)),
                ("C, cached", _wall_s(c, env, REPEAT))]
    print(f"start-up, `simrunner drive ... --laps 1` in a fresh process, median of {REPEAT} "
          f"(min, max), s:")
    med = {}
    for label, times in rows:
        med[label] = statistics.median(times)
        print(f"  {label:<24} {med[label]:6.2f}  ({min(times):.2f}, {max(times):.2f})")
    first = med["C, new"]
    margin = med["C, cached"] - med["python line_follower.py"]
    print(f"  first run of a new C controller: {first:.2f} s (target < {FIRST_RUN_TARGET_S:g} s: "
          f"{'met' if first < FIRST_RUN_TARGET_S else 'NOT met'})")
    print(f"  cached C - Python: {margin:+.2f} s (target < {CACHED_MARGIN_S:g} s: "
          f"{'met' if margin < CACHED_MARGIN_S else 'NOT met'})")
    return {"repeat": REPEAT, "target_first_s": FIRST_RUN_TARGET_S, "target_margin_s": CACHED_MARGIN_S,
            "rows": [{"run": label, "median_s": round(med[label], 3), "min_s": round(min(times), 3),
                      "max_s": round(max(times), 3)} for label, times in rows]}


def parts() -> None:
    """The C-only start-up parts, timed inside one process (robust to the interpreter's
    start-up, which varies with the machine's load)."""
    from simrunner.run.native import build_program, load_native
    from simrunner.run.native.build import inproc_library

    with tempfile.TemporaryDirectory() as tmp:
        old = os.environ.get("SIMRUNNER_CACHE_DIR")
        os.environ["SIMRUNNER_CACHE_DIR"] = str(Path(tmp) / "cache")
        try:
            src = Path(tmp) / "follower.c"
            (Path(tmp) / "lane_tracker.h").write_text((EXAMPLES / "lane_tracker.h").read_text())
            rows = []
            for i in range(REPEAT):
                src.write_text((EXAMPLES / "line_follower.c").read_text() + f"/* {i} */\n")
                t0 = time.perf_counter()
                inproc_library()  # the in-process host library (this process loaded one already)
                t1 = time.perf_counter()
                prog = build_program([src])
                t2 = time.perf_counter()
                build_program([src])
                t3 = time.perf_counter()
                ctrl = load_native(prog)  # the library opened for a run
                t4 = time.perf_counter()
                del ctrl
                rows.append((t1 - t0, t2 - t1, t3 - t2, t4 - t3))
        finally:
            if old is None:
                os.environ.pop("SIMRUNNER_CACHE_DIR", None)
            else:
                os.environ["SIMRUNNER_CACHE_DIR"] = old
    med = [statistics.median(col) for col in zip(*rows)]
    print(f"C start-up parts in one process, median of {REPEAT}, s: in-process host library "
          f"build {rows[0][0]:.3f} (first), compile + link of line_follower.c {med[1]:.3f}, "
          f"cached lookup {med[2]:.4f}, opening the library for a run {med[3]:.4f}")


def main() -> None:
    laps = closed_loop()
    parts_of_lap = split()
    parts()
    from bench.record import save

    save("c_controller", {"closed_loop": laps, "split": parts_of_lap, "start_up": start_up()})


if __name__ == "__main__":
    main()
