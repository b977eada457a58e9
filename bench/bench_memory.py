"""Memory of long runs (issue 13 item 16): the resident set size of a whole ``drive`` process
after 10 and after 60 simulated minutes must be about the same (the run log is streamed to
the CSV; only a bounded, thinned log stays in memory).

Each measurement is a fresh process: ``drive(examples/line_follower.py)`` on the default
track for MINUTES simulated minutes (laps unbounded), with ``--csv`` to a temporary file and
without; it reports the peak RSS (``ru_maxrss``) and the rows written.

    python -m bench memory                     # 10 and 60 simulated minutes
    BENCH_MEMORY_MINUTES=2,10 BENCH_MEMORY_CSV=no python -m bench memory   # other lengths, no CSV
    BENCH_REPO=/path/to/other/checkout python -m bench memory   # the same on another tree
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, resource, sys
from simrunner.run.runner import drive
minutes, csv = float(sys.argv[1]), (sys.argv[2] or None)
r = drive(sys.argv[3], laps=100000, time_limit_s=60.0 * minutes, csv=csv)
print(json.dumps({"outcome": str(r.outcome), "sim_time_s": r.sim_time_s, "wall_time_s": r.wall_time_s,
                  "rows": r.summary()["frames"], "log_rows": len(r.log),
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}))
"""


def measure(minutes: float, with_csv: bool, repo: Path) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        csv = str(Path(tmp) / "t.csv") if with_csv else ""
        env = dict(os.environ, PYTHONPATH=str(repo))
        out = subprocess.run([sys.executable, "-c", CHILD, str(minutes), csv,
                              str(repo / "examples" / "line_follower.py")],
                             env=env, cwd=repo, capture_output=True, text=True, check=True)
        result = json.loads(out.stdout.strip().splitlines()[-1])
        if with_csv:
            result["csv_mb"] = Path(csv).stat().st_size / 1e6
        return result


def main() -> None:
    repo = Path(os.environ.get("BENCH_REPO", REPO))
    minutes = [float(m) for m in os.environ.get("BENCH_MEMORY_MINUTES", "10,60").split(",")]
    print(f"repo {repo}")
    print(f"{'sim min':>8} {'csv':>4} {'outcome':>10} {'rows':>8} {'log rows':>9} {'peak RSS MB':>12} {'wall s':>7}")
    rows = []
    for with_csv in [c == "csv" for c in os.environ.get("BENCH_MEMORY_CSV", "no,csv").split(",")]:
        for m in minutes:
            t0 = time.perf_counter()
            r = measure(m, with_csv, repo)
            print(f"{m:8g} {'yes' if with_csv else 'no':>4} {r['outcome']:>10} {r['rows']:8d} "
                  f"{r['log_rows']:9d} {r['peak_rss_mb']:12.1f} {time.perf_counter() - t0:7.1f}", flush=True)
            rows.append({"minutes": m, "csv": with_csv, "rows": r["rows"], "log_rows": r["log_rows"],
                         "peak_rss_mb": round(r["peak_rss_mb"], 1)})
    if repo == REPO:  # another tree's figures are not this one's
        from bench.record import save
        from simrunner.telemetry.log import KEEP_ROWS

        save("memory", {"keep_rows": KEEP_ROWS, "rows": rows})


if __name__ == "__main__":
    main()
