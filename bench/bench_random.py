"""``trackgen random`` speed and validity: layouts per second, and how many of the emitted
layouts fail the full ``trackgen validate`` checks (meshes included).

``python -m bench random`` draws seeds 0..N-1 (N = ``NXPCUP_RANDOM_N``, default 10,000;
the full mesh check costs ~40-90 ms a layout, so 10,000 take several minutes on one core).
Reported: layouts per wall second and per CPU second of :func:`random_layout` (its own
2D checks), the attempts per layout, the crossings drawn, and the count of emitted layouts
that fail the full validation (target: 0) - the machine load is printed beside them.
"""
from __future__ import annotations

import collections
import os
import time

from trackgen.build import check_layout
from trackgen.layout import parse_layout
from trackgen.random import random_layout
from trackgen.validate import errors

TARGET_PER_S = 20.0


def main() -> None:
    n = int(os.environ.get("NXPCUP_RANDOM_N", "10000"))
    random_layout(0)  # imports, warm caches
    load = os.getloadavg()[0]
    t0, c0 = time.perf_counter(), time.process_time()
    texts = [random_layout(seed) for seed in range(n)]
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    attempts = [int(t.split("attempt ", 1)[1].split(")", 1)[0]) for t in texts]
    crossings = collections.Counter(t.count("second pass") for t in texts)
    print(f"machine load (1-min average) {load:.1f} on {os.cpu_count()} cores")
    print(f"random_layout: {n} layouts in {wall:.1f} s wall / {cpu:.1f} s CPU: "
          f"{n / wall:.1f} layouts/s wall, {n / cpu:.1f} per CPU-second "
          f"(target >= {TARGET_PER_S:g}/s)")
    print(f"attempts per layout: mean {sum(attempts) / n:.2f}, max {max(attempts)}; "
          f"crossings: {dict(sorted(crossings.items()))}")
    t0 = time.perf_counter()
    bad = []
    for seed, text in enumerate(texts):
        checked = check_layout(parse_layout(text, path=f"seed{seed}.txt"))
        if errors(checked.problems):
            bad.append((seed, str(errors(checked.problems)[0])))
    print(f"full validation (trackgen validate, meshes included): {len(bad)} invalid of {n} "
          f"({time.perf_counter() - t0:.0f} s)")
    for seed, problem in bad[:5]:
        print(f"  seed {seed}: {problem}")
    from bench.record import save

    save("random", {"n": n, "target_per_s": TARGET_PER_S, "per_cpu_s": round(n / cpu, 1),
                    "per_wall_s": round(n / wall, 1), "attempts_mean": round(sum(attempts) / n, 2),
                    "attempts_max": max(attempts), "invalid": len(bad),
                    "crossings": {str(k): v for k, v in sorted(crossings.items())}})


if __name__ == "__main__":
    main()
