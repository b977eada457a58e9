"""``simrunner batch`` throughput: 1 vs 2 local workers, laps per core-minute, per-run
overhead, and the Ray local cluster against the local pool (same rows).

``python -m bench batch``. The batch: ``examples/line_follower.py``, 1 lap of the bundled
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
"""
from __future__ import annotations

import importlib.util
import os
import statistics
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


def _ray(tmp: Path) -> None:
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
    for key, what in (("steady_run", "steady wall"), ("cpu_run", "steady CPU"),
                      ("wall_run", "wall incl. start-up")):
        loc, ray = (statistics.median(m[key] for m in runs[k]) for k in ("local", "ray"))
        print(f"  Ray vs local pool, {what} per run (median of {reps}): {1e3 * ray:.1f} vs "
              f"{1e3 * loc:.1f} ms = {100 * (ray - loc) / loc:+.1f} %")
    print(f"  rows identical (Ray and local, every repetition): {same}; target <= +10 % per run")


def main() -> None:
    print(f"machine load (1-min average) {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        results = {}
        for w in (1, 2):
            m = _batch(tmp / f"w{w}", workers=w)
            res = m["res"]
            laps = sum(r["laps_completed"] for r in res.rows)
            cpu = sum(r["cpu_time_s"] for r in res.rows)
            results[w] = m
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
        if importlib.util.find_spec("ray") is None:   # not imported: its private cluster sets
            print("ray: not installed (pip install 'nxpcup-sim[ray]'), Ray figures skipped")
            return                                     # its loopback switch first
        _ray(tmp)


if __name__ == "__main__":
    main()
