"""``simrunner batch`` throughput: 1 vs 2 local workers, laps per core-minute, per-run
overhead, and the Ray local cluster against the local pool (same rows).

``python -m bench batch``. The batch: ``examples/line_follower.py``, 1 lap of the bundled
track, ``NXPCUP_BATCH_RUNS`` runs (default 16: 2 values of v_max x 8 seeds). Reported:
wall time and runs/s for 1 and 2 workers (target: 2 workers >= 1.8 x 1 worker), laps per
core-minute (laps / (workers x wall minutes)), the per-run overhead of the pool (wall per run
on 1 worker minus a bare in-process ``drive()`` of the same run on a loaded track, as a
share of that run; target <= 5 % of a 10-s lap) and of Ray (per-run wall on Ray's local
cluster vs the local pool at the same worker count; target <= 10 %). The machine load
(1-minute average) is printed: these machines are shared, so compare the CPU column too.
"""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from simrunner.workflows.batch import deterministic, run_batch

REPO = Path(__file__).resolve().parents[1]
CTL = REPO / "examples" / "line_follower.py"


def _batch(out: Path, **kw):
    """(result, wall s incl. start-up, steady wall s per run): the steady rate counts the
    runs after each worker's first one (worker start-up excluded)."""
    n = int(os.environ.get("NXPCUP_BATCH_RUNS", "16"))
    arrivals: list[float] = []
    t0 = time.perf_counter()
    res = run_batch(CTL, out_dir=out, seeds=max(1, n // 2), params=["v_max=2.6,2.8"], plot=False,
                    time_limit_s=30.0, on_row=lambda row: arrivals.append(time.perf_counter()), **kw)
    w = res.workers
    steady = (arrivals[-1] - arrivals[w - 1]) / max(1, len(arrivals) - w)
    return res, time.perf_counter() - t0, steady


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


def main() -> None:
    print(f"machine load (1-min average) {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        results = {}
        for w in (1, 2):
            res, wall, steady = _batch(tmp / f"w{w}", workers=w)
            laps = sum(r["laps_completed"] for r in res.rows)
            cpu = sum(r["cpu_time_s"] for r in res.rows)
            results[w] = (res, steady)
            print(f"{w} worker(s): {len(res.rows)} runs in {wall:.1f} s incl. start-up; steady "
                  f"{1 / steady:.2f} runs/s = {60 * laps / len(res.rows) / steady / w:.1f} laps per "
                  f"core-minute; {60 * laps / cpu:.0f} laps per CPU-minute of run loop")
        speedup = results[1][1] / results[2][1]
        same = [deterministic(r) for r in results[1][0].rows] == [deterministic(r) for r in results[2][0].rows]
        print(f"2 vs 1 worker: {speedup:.2f}x (target >= 1.8x); rows identical: {same}")
        n = len(results[1][0].rows)
        bare = _bare(n)
        per_run = results[1][1]
        print(f"per run: bare drive() {bare * 1e3:.0f} ms, batch on 1 worker (steady) "
              f"{per_run * 1e3:.0f} ms: overhead {100 * (per_run - bare) / bare:+.1f} %")
        try:
            import ray  # noqa: F401
        except ImportError:
            print("ray: not installed (pip install 'nxpcup-sim[ray]'), Ray figures skipped")
            return
        res, wall, steady = _batch(tmp / "ray", workers=2, ray="local")
        same = [deterministic(r) for r in res.rows] == [deterministic(r) for r in results[2][0].rows]
        local = results[2][1]
        print(f"Ray local cluster, 2 workers: {len(res.rows)} runs in {wall:.1f} s incl. Ray "
              f"start-up; steady per run {1e3 * steady:.0f} ms vs local pool {1e3 * local:.0f} ms: "
              f"{100 * (steady - local) / local:+.1f} %; rows identical: {same}")


if __name__ == "__main__":
    main()
