"""``simrunner batch`` throughput: 1 vs 2 local workers, laps per core-minute, per-run
overhead, and the Ray local cluster against the local pool (same rows).

``python -m bench batch`` (``NXPCUP_BATCH_SKIP_SHORT=1``: without the short batches below).
The batch: ``examples/line_follower.py``, 1 lap of the bundled
track, ``NXPCUP_BATCH_RUNS`` runs (default 16: 2 values of v_max x 8 seeds). Reported:
wall time and runs/s for 1 and 2 workers (target: 2 workers >= 1.8 x 1 worker), laps per
core-minute (laps / (workers x wall minutes)), the per-run overhead of the pool (wall per run
on 1 worker minus a bare in-process ``drive()`` of the same run on a loaded track, as a
share of that run; target <= 5 % of a 10-s lap) and of Ray (Ray's local cluster vs the local
pool at 2 workers; target <= 10 %).

Ray and the local pool are measured alternately, ``NXPCUP_BATCH_REPS`` times each (default
2), in this one bench run. Per run, each of: the wall time including start-up (Ray's too);
the steady wall time (each worker's rows after its first one: ``(runs - 1) / (last row -
first row)``, summed over the workers); and the steady CPU time of every process of the
batch (this driver and its descendants: workers, forkserver, Ray's daemons), read from
``/proc`` at each row between the moment every worker has delivered a row and the last row.
The machines are shared: the CPU figure is the one the other jobs disturb least, and the
machine load (1-minute average) is printed beside each line.

First, the short batch where start-up shows (issue 50): 8 one-lap runs of the line follower
on the bundled track with the default settings, 1 and 2 workers alternately
``NXPCUP_BATCH_SHORT_REPS`` times (default 5), best and median wall time of each and the
ratio of the bests (target: 2 workers >= 1.7 x 1 worker, rows identical). Three figures:
the wall time of the ``run_batch`` call in this process (the simulator imported already, as
in a sweep script); its CPU time on the critical path (:class:`_CriticalCpu`: what the wall
time is on an idle machine, and the figure the shared machine's other jobs disturb least);
and the wall time of the whole ``simrunner batch`` command in a fresh process (interpreter
start, imports and writing the results included).
"""
from __future__ import annotations

import importlib.util
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from simrunner.workflows.batch import deterministic, run_batch

REPO = Path(__file__).resolve().parents[1]
CTL = REPO / "examples" / "line_follower.py"
TICK_S = 1.0 / os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 0.01


def _tree_cpu_s(root: int) -> dict[str, float]:
    """CPU seconds (user + system) of ``root`` and its live descendants, by process name
    (the root is ``"driver"``); empty where there is no ``/proc``."""
    procs: dict[int, tuple[int, str, float]] = {}
    for entry in os.listdir("/proc") if os.path.isdir("/proc") else ():
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        name, fields = stat[stat.index("(") + 1:stat.rindex(")")], stat[stat.rindex(")") + 2:].split()
        procs[int(entry)] = (int(fields[1]), name, (int(fields[11]) + int(fields[12])) * TICK_S)
    out: dict[str, float] = {}
    todo = [root]
    while todo:
        pid = todo.pop()
        if pid in procs:
            name = "driver" if pid == root else procs[pid][1]
            out[name] = out.get(name, 0.0) + procs[pid][2]
            todo += [c for c, (ppid, _, _) in procs.items() if ppid == pid]
    return out


class _Probe:
    """``on_row`` of a bench batch: each row's arrival time and the batch's CPU so far (the
    probe's own CPU is taken off the driver's)."""

    def __init__(self):
        self.samples: list[tuple[float, dict[str, float]]] = []
        self.own_cpu_s = 0.0

    def __call__(self, row: dict) -> None:
        c0 = time.process_time()
        cpu = _tree_cpu_s(os.getpid())
        cpu["driver"] = cpu.get("driver", 0.0) - self.own_cpu_s
        self.samples.append((time.monotonic(), cpu))
        self.own_cpu_s += time.process_time() - c0


def _batch(out: Path, **kw) -> dict:
    """One batch: its result, the wall per run including start-up, the steady wall and CPU
    per run (and the CPU by process name)."""
    n = int(os.environ.get("NXPCUP_BATCH_RUNS", "16"))
    probe = _Probe()
    t0 = time.monotonic()
    res = run_batch(CTL, out_dir=out, seeds=max(1, n // 2), params=["v_max=2.6,2.8"], plot=False,
                    time_limit_s=30.0, on_row=probe, **kw)
    t1 = time.monotonic()
    wall = t1 - t0
    workers = [w for w in res.worker_timing if w.runs >= 2]
    rate = sum((w.runs - 1) / (w.last_row_at - w.first_row_at) for w in workers)
    between = sum(w.last_row_at - w.first_row_at for w in workers) / sum(w.runs - 1 for w in workers)
    loop = sum(r["wall_time_s"] for r in res.rows) / len(res.rows)
    all_busy = max(w.first_row_at for w in res.worker_timing if w.first_row_at is not None)
    window = [s for s in probe.samples if s[0] >= all_busy]
    (_, cpu_a), (_, cpu_b) = window[0], window[-1]
    by_name = {k: (v - cpu_a.get(k, 0.0)) / max(1, len(window) - 1) for k, v in cpu_b.items()}
    first, last = res.worker_timing[0].started_at, max(w.last_row_at or t0 for w in res.worker_timing)
    ready = max(w.ready_at or first for w in res.worker_timing)
    return {"to_first_worker": first - t0, "to_ready": ready - t0, "after_last_row": t1 - last,
            "res": res, "wall_run": wall / len(res.rows), "steady_run": 1.0 / rate,
            "cpu_run": sum(by_name.values()), "cpu_by_name": by_name, "wall": wall,
            "load": os.getloadavg()[0],
            "gap_run": between - loop}


def _bare(n: int) -> float:
    """Wall seconds per run of ``drive()`` in this process on a loaded track."""
    from simrunner.run.runner import default_track, drive
    from simrunner.track import load_track
    from vehicle.description import load_car

    car = load_car(None)
    track = load_track(default_track(), car=car)
    drive(CTL, track=track, car=car)  # warm
    t0 = time.perf_counter()
    for i in range(n):
        drive(CTL, track=track, car=car, seed=i % 8, time_limit_s=30.0,
              params={"v_max": 2.6 + 0.2 * (i % 2)})
    return (time.perf_counter() - t0) / n


def _line(label: str, m: dict) -> str:
    top = sorted(((v, k) for k, v in m["cpu_by_name"].items() if v >= 5e-4), reverse=True)
    return (f"  {label:5s} {len(m['res'].rows)} runs in {m['wall']:.1f} s = {1e3 * m['wall_run']:.0f} ms/run "
            f"incl. start-up (first worker started at {m['to_first_worker']:.1f} s, all ready at "
            f"{m['to_ready']:.1f} s, end {m['after_last_row']:.1f} s after the last row); steady "
            f"{1e3 * m['steady_run']:.1f} ms/run wall, {1e3 * m['cpu_run']:.1f} ms/run CPU ("
            + ", ".join(f"{k} {1e3 * v:.1f}" for v, k in top) + f"); a worker's rows come "
            f"{1e3 * m['gap_run']:.1f} ms more apart than its runs' loops last; load {m['load']:.1f}")


def _ray(tmp: Path) -> dict:
    """Ray against the local pool (docstring); returns the figures it printed."""
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    reps = int(os.environ.get("NXPCUP_BATCH_REPS", "2"))
    runs: dict[str, list[dict]] = {"local": [], "ray": []}
    print(f"Ray local cluster vs the local pool, 2 workers each, alternately x{reps}:")
    for i in range(reps):
        for label, kw in (("local", {}), ("ray", {"ray": "local"})):
            m = _batch(tmp / f"{label}{i}", workers=2, **kw)
            runs[label].append(m)
            print(_line(label, m), flush=True)
    rows = {label: [[deterministic(r) for r in m["res"].rows] for m in ms] for label, ms in runs.items()}
    same = all(r == rows["local"][0] for r in rows["local"] + rows["ray"])
    figures = []
    for key, what in (("steady_run", "steady wall"), ("cpu_run", "steady CPU"),
                      ("wall_run", "wall incl. start-up")):
        loc, ray = (statistics.median(m[key] for m in runs[k]) for k in ("local", "ray"))
        print(f"  Ray vs local pool, {what} per run (median of {reps}): {1e3 * ray:.1f} vs "
              f"{1e3 * loc:.1f} ms = {100 * (ray - loc) / loc:+.1f} %")
        figures.append({"what": what, "ray_ms": round(1e3 * ray, 1), "local_ms": round(1e3 * loc, 1),
                         "change": round((ray - loc) / loc, 3)})
    print(f"  rows identical (Ray and local, every repetition): {same}; target <= +10 % per run")
    return {"repetitions": reps, "rows_identical": same, "target_change": 0.10, "figures": figures,
            "start": [{"how": label, "to_first_worker_s": round(statistics.median(m["to_first_worker"] for m in ms), 2),
                       "to_ready_s": round(statistics.median(m["to_ready"] for m in ms), 2),
                       "after_last_row_s": round(statistics.median(m["after_last_row"] for m in ms), 2)}
                      for label, ms in runs.items()]}


_PYCACHE = tempfile.mkdtemp(prefix="bench-batch-pycache-")


def _short_cli(out: Path, workers: int) -> float:
    """Wall seconds of ``simrunner batch`` (8 one-lap runs) in a fresh process, which caches its
    compiled modules as on a student's machine (``PYTHONDONTWRITEBYTECODE`` unset, the cache in a
    temp folder: without it each start compiles ~80 modules again, ~0.1 s)."""
    code = "import sys; from simrunner.cli import run; sys.argv[0] = 'simrunner'; run()"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPYCACHEPREFIX"] = _PYCACHE
    t0 = time.monotonic()
    subprocess.run([sys.executable, "-c", code, "batch", str(CTL), "--seeds", "8", "--workers",
                    str(workers), "--no-plot", "-o", str(out)], check=True, capture_output=True, env=env)
    return time.monotonic() - t0


def _procs() -> dict[int, tuple[int, float]]:
    """Every process: pid -> (parent pid, CPU seconds so far)."""
    out = {}
    for entry in os.listdir("/proc") if os.path.isdir("/proc") else ():
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            fields = stat[stat.rindex(")") + 2:].split()
            out[int(entry)] = (int(fields[1]), (int(fields[11]) + int(fields[12])) * TICK_S)
    return out


class _CriticalCpu:
    """``on_row`` of a short batch: the CPU time on its critical path, what its wall time is on
    an idle machine (the shared machine's other jobs stretch wall times, hardly CPU times):
    this process's CPU during the batch, plus that of every descendant that has children
    (a forkserver, started before any worker), plus the largest of the workers' (the
    leaves; read at each row, while they live)."""

    def __init__(self):
        self.before = _procs()
        self.cpu0 = time.process_time()
        self.last: dict[int, tuple[int, float]] = {}

    def __call__(self, row: dict) -> None:
        procs, me = _procs(), os.getpid()
        tree, todo = {}, [me]
        while todo:
            pid = todo.pop()
            kids = [c for c, (ppid, _) in procs.items() if ppid == pid]
            todo += kids
            if pid != me:
                tree[pid] = (len(kids), procs[pid][1] - self.before.get(pid, (0, 0.0))[1])
        self.last.update(tree)

    def total_s(self) -> float:
        inner = sum(cpu for kids, cpu in self.last.values() if kids)
        leaves = [cpu for kids, cpu in self.last.values() if not kids]
        return time.process_time() - self.cpu0 + inner + max(leaves, default=0.0)


def _short(tmp: Path) -> None:
    """8 one-lap runs, 1 vs 2 workers, in this process and as a fresh command (docstring)."""
    reps = int(os.environ.get("NXPCUP_BATCH_SHORT_REPS", "5"))
    walls: dict[tuple[str, int], list[float]] = {}
    rows: dict[int, list] = {}
    run_batch(CTL, out_dir=tmp / "short-warm", seeds=1, workers=1, plot=False)  # imports
    for i in range(reps):
        for w in (1, 2):
            probe = _CriticalCpu()
            t0 = time.monotonic()
            res = run_batch(CTL, out_dir=tmp / f"short-{w}-{i}", seeds=8, workers=w, plot=False,
                            on_row=probe)
            walls.setdefault(("in-process", w), []).append(time.monotonic() - t0)
            walls.setdefault(("critical CPU", w), []).append(probe.total_s())
            rows.setdefault(w, [deterministic(r) for r in res.rows])
            walls.setdefault(("command", w), []).append(_short_cli(tmp / f"short-cli-{w}-{i}", w))
    same = rows[1] == rows[2] and all(r["outcome"] == "finished" for r in rows[1])
    print(f"8 one-lap runs (bundled track, default settings), 1 vs 2 workers, x{reps} alternately, "
          f"load {os.getloadavg()[0]:.1f}:")
    for how in ("in-process", "critical CPU", "command"):
        one, two = walls[(how, 1)], walls[(how, 2)]
        print(f"  {how:12s} 1 worker best {min(one):.2f} s (median {statistics.median(one):.2f}), "
              f"2 workers best {min(two):.2f} s (median {statistics.median(two):.2f}): "
              f"{min(one) / min(two):.2f}x")
    print(f"  rows identical (1 and 2 workers, all finished): {same}; target >= 1.7x")
    from bench.record import save

    save("batch_short", {"repetitions": reps, "rows_identical": same, "target_ratio": 1.7, "figures": [
        {"how": how, "one_worker_s": round(min(walls[(how, 1)]), 3), "two_workers_s": round(min(walls[(how, 2)]), 3),
         "ratio": round(min(walls[(how, 1)]) / min(walls[(how, 2)]), 3)}
        for how in ("in-process", "critical CPU", "command")]})


def main() -> None:
    print(f"machine load (1-min average) {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if not os.environ.get("NXPCUP_BATCH_SKIP_SHORT"):
            _short(tmp)
        if os.environ.get("NXPCUP_BATCH_SHORT_ONLY"):
            return
        results, laps_per_core_min = {}, {}
        for w in (1, 2):
            m = _batch(tmp / f"w{w}", workers=w)
            res = m["res"]
            laps = sum(r["laps_completed"] for r in res.rows)
            cpu = sum(r["cpu_time_s"] for r in res.rows)
            results[w] = m
            laps_per_core_min[w] = 60 * laps / len(res.rows) / m["steady_run"] / w
            print(f"{w} worker(s): {len(res.rows)} runs in {m['wall']:.1f} s incl. start-up; steady "
                  f"{1 / m['steady_run']:.2f} runs/s = "
                  f"{60 * laps / len(res.rows) / m['steady_run'] / w:.1f} laps per core-minute; "
                  f"{60 * laps / cpu:.0f} laps per CPU-minute of run loop")
        speedup = results[1]["steady_run"] / results[2]["steady_run"]
        same = ([deterministic(r) for r in results[1]["res"].rows]
                == [deterministic(r) for r in results[2]["res"].rows])
        print(f"2 vs 1 worker: {speedup:.2f}x (target >= 1.8x); rows identical: {same}")
        n = len(results[1]["res"].rows)
        bare = _bare(n)
        per_run = results[1]["steady_run"]
        print(f"per run: bare drive() {bare * 1e3:.0f} ms, batch on 1 worker (steady) "
              f"{per_run * 1e3:.0f} ms: overhead {100 * (per_run - bare) / bare:+.1f} %")
        figures = {"runs": n, "target_speedup": 1.8, "target_overhead": 0.05, "rows_identical": same,
                   "workers": [{"workers": w, "runs_per_s": round(1 / results[w]["steady_run"], 2),
                                "laps_per_core_min": round(laps_per_core_min[w])} for w in (1, 2)],
                   "speedup": round(speedup, 3), "bare_ms": round(bare * 1e3, 1), "pool_ms": round(per_run * 1e3, 1),
                   "overhead": round((per_run - bare) / bare, 3), "ray": None}
        if importlib.util.find_spec("ray") is None:   # not imported: its private cluster sets
            print("ray: not installed (pip install 'nxpcup-sim[ray]'), Ray figures skipped")
        else:                                          # its loopback switch first
            figures["ray"] = _ray(tmp)
    from bench.record import save

    save("batch", figures)


if __name__ == "__main__":
    main()
