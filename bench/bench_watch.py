"""``simrunner drive --watch``: turnaround from saving the controller to its result.

The watcher (:func:`simrunner.run.watch.watch_runs`, what ``drive --watch`` runs) keeps the
default track (the thesis figure 8) loaded; the bench saves ``examples/line_follower.py``
(copied to a temporary folder) ``REPEAT`` times with a changed speed and times each save to
the end of its one-lap run: the polling delay, loading and compiling the file, building the
car and camera, the lap itself and the judging. Target (issue 13): under 0.5 s.
Columns: median / min / max seconds (wall, and CPU time of this process, which a busy
machine inflates less), the lap's own loop time (wall) and the load average.
"""
from __future__ import annotations

import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
REPEAT = 5
TARGET_S = 0.5


def turnarounds_s(repeat: int = REPEAT) -> tuple[list[float], list[float], list[float], list[str]]:
    """(save-to-result wall seconds, the same in process CPU seconds, loop wall seconds,
    outcomes) of ``repeat`` saves."""
    from simrunner.run.watch import watch_runs

    with tempfile.TemporaryDirectory() as tmp:
        ctrl = Path(tmp) / "line_follower.py"
        shutil.copy(REPO / "examples" / "line_follower.py", ctrl)
        source = ctrl.read_text()
        runs = watch_runs(ctrl, laps=1, poll_s=0.02)
        next(runs)  # the first run: track load and warm-up
        times, cpus, loops, outcomes = [], [], [], []
        for i in range(repeat):
            text = source + f"\n# save {i}\n"
            t0, c0 = time.perf_counter(), time.process_time()
            ctrl.write_text(text)
            event = next(runs)
            times.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
            loops.append(event.result.wall_time_s)
            outcomes.append(str(event.result.outcome))
        runs.close()
    return times, cpus, loops, outcomes


def main() -> None:
    load = os.getloadavg()[0]
    times, cpus, loops, outcomes = turnarounds_s()
    print(f"{'save -> result, one lap (s)':<36} {'median':>7} {'min':>7} {'max':>7}  target")
    print(f"{'drive --watch, default track':<36} {statistics.median(times):7.3f} {min(times):7.3f} "
          f"{max(times):7.3f}  < {TARGET_S} s "
          f"({'met' if statistics.median(times) < TARGET_S else 'not met'})")
    print(f"{'  the same in CPU seconds':<36} {statistics.median(cpus):7.3f} {min(cpus):7.3f} "
          f"{max(cpus):7.3f}  (less sensitive to a busy machine)")
    print(f"{'  of which the lap loop (wall)':<36} {statistics.median(loops):7.3f} {min(loops):7.3f} "
          f"{max(loops):7.3f}")
    print(f"outcomes: {', '.join(sorted(set(outcomes)))}; load average {load:.1f} -> "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    from bench.record import save

    save("watch", {"repeat": REPEAT, "target_s": TARGET_S, "outcomes": sorted(set(outcomes)), "rows": [
        {"what": what, "median_s": round(statistics.median(v), 3), "min_s": round(min(v), 3), "max_s": round(max(v), 3)}
        for what, v in (("wall", times), ("cpu", cpus), ("loop", loops))]})


if __name__ == "__main__":
    main()
