"""Bench of the gap workflow (issue 4 section 6) on synthetic logs with a hidden effect.

Every fourth trial is effect-free ("none"), the others cycle through the catalogue
(:func:`trial_effect`); each trial draws a plan seed, a
magnitude, nuisance mass/friction and noise from ``numpy.random.default_rng([SEED, k])``
(:func:`simrunner.workflows.gap.synth.make_measured_log`) and runs the whole catalogue
(``run_gap(jobs=1)``); trials run in parallel processes. Reported:

* naming accuracy overall, per effect, and by signal-to-noise ratio. SNR of a trial: the
  RMS over the replay windows of the difference the hidden effect makes to x, y, yaw and
  speed (replays from the exact states with the true car, with and without the effect),
  each divided by its noise sigma, averaged in square over the four signals, square-rooted;
* false claims on effect-free logs;
* median relative parameter error |fit - true| / |true - neutral| (/ |true| when the
  neutral value is infinite) over correctly named trials;
* median held-out position RMSE after/before over trials with an effect (against the
  noisy measured log, as the workflow reports it), per signal, and on the signal the
  hidden effect changes most (known from the truth); the same ratios against the smoothed
  measured states, where the sensor noise no longer sets a floor;
* wall time of one full-length log through the whole catalogue on 2 processes.

Targets: >= 90 % named where SNR >= 3, <= 5 % false claims, median parameter error
<= 10 %, median RMSE after/before <= 0.5.

``python -m bench.bench_gap [--trials N] [--jobs J] [--short] [--out FILE.jsonl] [--no-wall]``
(``--table FILE.jsonl`` prints the table of saved rows);
``python -m bench`` runs ``main()`` with the defaults (100 trials: about an hour on 2 cores).
"""
from __future__ import annotations

import argparse
import json
import math
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

SEED = 20240
SHORT_TRIALS = 16  # every effect at least once, four effect-free
NONE_EVERY = 4


def _trial(k: int) -> dict:
    from simrunner.workflows.gap.fit import _quiet_worker
    from simrunner.workflows.gap.logs import derive
    from simrunner.workflows.gap.replay import make_windows, replay
    from simrunner.workflows.gap.report import run_gap
    from simrunner.workflows.gap.synth import (NOISE_POS_M, NOISE_SPEED_MPS, NOISE_YAW_RAD, RANGES, make_measured_log)
    from simrunner.car.effects import EFFECTS

    _quiet_worker()
    effect = trial_effect(k, list(RANGES))
    t0 = time.perf_counter()
    log, truth = make_measured_log(effect, rng=np.random.default_rng([SEED, k]))
    result = run_gap(log, jobs=1)
    row = {"trial": k, "effect": effect or "none", "named": result.effect, "value": truth.value,
           "field": truth.field, "fitted": result.parameters.get(truth.field) if truth.field else None,
           "rmse_before": result.rmse_before, "rmse_after": result.rmse_after,
           "gap_ratio": result.gap_after / result.gap_before,
           "best": result.ranking[0].effect, "best_delta_bic": result.ranking[0].delta_bic,
           "best_improvement": result.ranking[0].improvement}
    # the same held-out RMSE against the smoothed measured states (sensor noise mostly removed)
    row["rmse_smooth_before"] = result.rmse_smoothed_before
    row["rmse_smooth_after"] = result.rmse_smoothed_after
    if effect is not None:
        exact, _ = make_measured_log(effect, rng=np.random.default_rng([SEED, k]), noise=False)
        d = derive(exact, truth.car.chassis.wheelbase_m, truth.car.steering.limit_rad)
        w = make_windows(exact)
        neutral = EFFECTS[effect].neutral[0]
        from simrunner.car.effects import with_effects

        p1 = replay(truth.car, exact, d, w)
        p0 = replay(with_effects(truth.car, **{truth.field: neutral}), exact, d, w)
        dyaw = (p1.yaw_rad - p0.yaw_rad + math.pi) % (2 * math.pi) - math.pi
        ms = [np.nanmean(((p1.x_m - p0.x_m) / NOISE_POS_M) ** 2), np.nanmean(((p1.y_m - p0.y_m) / NOISE_POS_M) ** 2),
              np.nanmean((dyaw / NOISE_YAW_RAD) ** 2), np.nanmean(((p1.speed_mps - p0.speed_mps) / NOISE_SPEED_MPS) ** 2)]
        row["snr"] = float(np.sqrt(np.mean(ms)))
        # the report signal the hidden effect changes most (relative to its noise), from the truth
        row["most_affected"] = max((("position_m", 0.5 * (ms[0] + ms[1])), ("yaw_rad", ms[2]),
                                    ("speed_mps", ms[3])), key=lambda p: p[1])[0]
        if row["fitted"] is not None and result.effect == effect:
            ref = abs(truth.value) if math.isinf(neutral) else abs(truth.value - neutral)
            row["param_rel_err"] = abs(row["fitted"] - truth.value) / ref
    row["wall_s"] = time.perf_counter() - t0
    return row


def trial_effect(k: int, effects: list[str]) -> str | None:
    """The hidden effect of trial ``k``: every :data:`NONE_EVERY`-th trial is effect-free
    (so false claims are measured on a quarter of the trials), the others cycle through
    ``effects``."""
    if k % NONE_EVERY == 0:
        return None
    return effects[(k - 1 - k // NONE_EVERY) % len(effects)]


def _table(rows: list[dict]) -> str:
    med = lambda v: float(np.median(v)) if len(v) else float("nan")  # noqa: E731
    lines = [f"{'effect':<20}{'n':>4}{'named':>7}{'med SNR':>9}{'med p.err':>11}{'med RMSE a/b':>14}"]
    for eff in sorted({r["effect"] for r in rows}, key=lambda e: (e != "none", e)):
        rs = [r for r in rows if r["effect"] == eff]
        ok = sum(r["named"] == eff for r in rs)
        snr = med([r["snr"] for r in rs if "snr" in r])
        perr = med([r["param_rel_err"] for r in rs if "param_rel_err" in r])
        ratio = med([r["rmse_after"]["position_m"] / r["rmse_before"]["position_m"] for r in rs])
        lines.append(f"{eff:<20}{len(rs):>4}{ok:>4}/{len(rs):<2}{snr:>9.1f}{perr:>11.1%}{ratio:>14.2f}")
    eff_rows = [r for r in rows if r["effect"] != "none"]
    none_rows = [r for r in rows if r["effect"] == "none"]
    hi = [r for r in eff_rows if r.get("snr", 0) >= 3]
    lo = [r for r in eff_rows if r.get("snr", 0) < 3]
    acc = lambda rs: (sum(r["named"] == r["effect"] for r in rs) / len(rs)) if rs else float("nan")  # noqa: E731
    lines += [
        "",
        f"named overall (with effect): {acc(eff_rows):.1%} of {len(eff_rows)}",
        f"named where SNR >= 3: {acc(hi):.1%} of {len(hi)}   (target >= 90 %)",
        f"named where SNR < 3: {acc(lo):.1%} of {len(lo)}",
        "named by SNR: " + ", ".join(
            f"[{a:g}, {b:g}): {acc(rs):.0%} of {len(rs)}" for a, b in ((0, 1), (1, 3), (3, 10), (10, math.inf))
            for rs in [[r for r in eff_rows if a <= r.get("snr", 0) < b]]),
        f"false claims on effect-free logs: {sum(r['named'] != 'none' for r in none_rows)} of {len(none_rows)}"
        f"   (target <= 5 %)",
        f"effect-free logs, best candidate: max delta_BIC {max([r['best_delta_bic'] for r in none_rows], default=float('nan')):.1f}, "
        f"max improvement {max([r['best_improvement'] for r in none_rows], default=float('nan')):.2%}",
        f"median parameter error (correctly named): {med([r['param_rel_err'] for r in eff_rows if 'param_rel_err' in r]):.1%}"
        f"   (target <= 10 %)",
        f"median held-out position RMSE after/before (with effect): "
        f"{med([r['rmse_after']['position_m'] / r['rmse_before']['position_m'] for r in eff_rows]):.2f}   (target <= 0.5)",
        "median held-out RMSE after/before per signal (with effect): " + ", ".join(
            f"{s} {med([r['rmse_after'][s] / r['rmse_before'][s] for r in eff_rows]):.2f}"
            for s in ("position_m", "yaw_rad", "speed_mps", "yaw_rate_radps")),
        f"median held-out RMSE after/before of the signal the effect changes most (from the truth): "
        f"{med([r['rmse_after'][r['most_affected']] / r['rmse_before'][r['most_affected']] for r in eff_rows if 'most_affected' in r]):.2f}",
        "against the smoothed measured states (noise mostly removed), median after/before: " + ", ".join(
            f"{s} {med([r['rmse_smooth_after'][s] / r['rmse_smooth_before'][s] for r in eff_rows if 'rmse_smooth_after' in r]):.2f}"
            for s in ("position_m", "yaw_rad", "speed_mps")),
        f"median held-out gap after/before (normalised residuals, all signals; RMS ratio): "
        f"{med([math.sqrt(r['gap_ratio']) for r in eff_rows if 'gap_ratio' in r]):.2f}",
        f"median wall time per trial (1 process): {med([r['wall_s'] for r in rows]):.0f} s",
    ]
    return "\n".join(lines)


def wall_time_one_log(jobs: int = 2) -> float:
    """Seconds for one full plan-length log through the whole catalogue with ``jobs``."""
    from simrunner.workflows.gap.report import run_gap
    from simrunner.workflows.gap.synth import make_measured_log

    log, _ = make_measured_log("steering_offset", rng=np.random.default_rng(SEED))
    t0 = time.perf_counter()
    run_gap(log, jobs=jobs)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="gap workflow bench")
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--short", action="store_true", help=f"{SHORT_TRIALS} trials (every effect once)")
    ap.add_argument("--out", type=Path, default=None, help="append per-trial rows (JSON lines)")
    ap.add_argument("--no-wall", action="store_true", help="skip the one-log wall-time measurement")
    ap.add_argument("--table", type=Path, default=None, help="only print the table of a --out file")
    a = ap.parse_args([] if argv is None else argv)
    if a.table:
        print(_table(sorted((json.loads(ln) for ln in a.table.read_text().splitlines() if ln.strip()),
                            key=lambda r: r["trial"])))
        return
    n = SHORT_TRIALS if a.short else a.trials
    if not a.no_wall:
        print(f"one {67:d}-s log, whole catalogue, {a.jobs} processes: {wall_time_one_log(a.jobs):.0f} s wall",
              flush=True)
    rows = []
    with ProcessPoolExecutor(max_workers=a.jobs) as pool:
        futures = [pool.submit(_trial, k) for k in range(n)]
        for fut in as_completed(futures):
            row = fut.result()
            rows.append(row)
            if a.out:
                with a.out.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    rows.sort(key=lambda r: r["trial"])
    print(_table(rows))


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
