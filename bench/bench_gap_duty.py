"""``simrunner gap`` on synthetic duty logs of a car on slip tyres (issue 51): are the motor's,
the H-bridge's and the tyres' hidden numbers named?

Each trial plays the excitation plan (``simrunner excite``) on the default car driven by duty
(``drive.command = "duty"``) on slip tyres (``wheels.tyre_model = "slip"``), with hidden effects
drawn from :data:`GROUPS` (trial ``k``: none when ``k % 4 == 0``, else one effect, two from
different groups when ``k`` is even) at magnitudes from ``synth.RANGES``, and the H-bridge
coasting in truth every third trial (the car file says brake), plus the synthetic logs' usual
nuisance (mass and grip +-3 %) and noise. ``run_gap(log, car file)`` then names what it finds.

Figures (targets of issue 51): hidden effects named where their SNR (``bench_gap``'s
definition: RMS over the sensors of the exact effect's change / the sensor noise) >= 3
(>= 90 %); median relative error of the named parameters (<= 15 %); effect-free logs with an
effect named (<= 5 %); the H-bridge mode chosen right. ``--results`` writes
``bench/results/gap_duty.json``.

    python -m bench.bench_gap_duty [--trials 12] [--first 0] [--jobs 2] [--results]
    python -m bench.bench_gap_duty --null 20 --results    # 20 effect-free trials: false claims
    python -m bench.bench_gap_duty --only 2,5 --results   # these trials again

``--results`` merges: a trial run again replaces its row; the note says which trials came
from which commit.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from bench.gap_scoring import SNR_MIN, method_row, replay_snr

SEED = 20251
GROUPS = {"motor": ("accel_scale", "speed_scale"), "losses": ("rolling_resistance", "drag"),
          "tyres": ("tyre_stiffness", "tyre_balance", "tyre_relaxation"), "grip": ("friction",)}
RESULTS = Path(__file__).resolve().parent / "results" / "gap_duty.json"
TARGETS = {"named_hi": 0.90, "median_error": 0.15, "false_claims": 0.05}


def car_file():
    """The car file of every trial: the default car, driven by duty, on slip tyres."""
    from vehicle.description import CarDescription

    base = CarDescription()
    return base.replace(drive=dataclasses.replace(base.drive, command="duty", front_share=0.0),
                        wheels=dataclasses.replace(base.wheels, tyre_model="slip"))


def design(k: int) -> tuple[list[str], str, np.random.Generator]:
    """``(hidden effects, true H-bridge mode, rng for make_measured_log)`` of trial ``k``."""
    rng = np.random.default_rng([SEED, k])
    hbridge = "coast" if k % 3 == 2 else "brake"
    if k % 4 == 0:
        return [], hbridge, rng
    names = list(GROUPS)
    picked = rng.choice(len(names), size=2 if k % 2 == 0 else 1, replace=False)
    return [str(rng.choice(GROUPS[names[i]])) for i in sorted(picked)], hbridge, rng


def snr(k: int) -> dict[str, float]:
    """Each hidden effect's SNR: its change of the exact log's replay over the sensor noise."""
    from simrunner.car.effects import neutral_car
    from simrunner.workflows.gap.logs import duty_commands
    from simrunner.workflows.gap.synth import NOISE_POS_M, NOISE_SPEED_MPS, NOISE_YAW_RAD, make_measured_log

    effects, hbridge, rng = design(k)
    if not effects:
        return {}
    exact, truth = make_measured_log(effects, rng=rng, noise=False, car=car_file(), hbridge=hbridge)
    sigma = {"x_m": NOISE_POS_M, "y_m": NOISE_POS_M, "yaw_rad": NOISE_YAW_RAD, "speed_mps": NOISE_SPEED_MPS}
    # the truth's nuisance and H-bridge, no effect; replayed by duty as run_gap does
    return replay_snr(neutral_car(truth.car), duty_commands(exact), effects, truth.values, sigma)


def trial(k: int) -> dict:
    from simrunner.workflows.gap.fit import _quiet_worker
    from simrunner.workflows.gap.synth import make_measured_log
    from simrunner.workflows.gap.workflow import run_gap

    _quiet_worker()
    effects, hbridge, rng = design(k)
    log, truth = make_measured_log(effects or None, rng=rng, car=car_file(), hbridge=hbridge)
    t0 = time.perf_counter()
    result = run_gap(log, car_file(), jobs=1)
    wall = time.perf_counter() - t0
    held = {"gap_before": result.gap_before, "gap_after": result.gap_after,
            "rmse_before": result.rmse_before, "rmse_after": result.rmse_after}
    return {"trial": k, "effects": effects, "values": truth.values, "hbridge": hbridge,
            "hbridge_chosen": (result.settings.get("hbridge") or {}).get("chosen"), "snr": snr(k),
            "chain": method_row(result.effects, result.parameters, truth.values, effects, held, wall, None,
                                result.parameter_sigma, result.parameter_spans),
            "glitches": len(result.glitches), "wall_s": wall}


def figures(rows: list[dict]) -> dict:
    hi = [r["chain"]["per_effect"][e]["named"] for r in rows for e in r["effects"] if r["snr"].get(e, 0.0) >= SNR_MIN]
    errs = [p["rel_err"] for r in rows for p in r["chain"]["per_effect"].values()
            if p["named"] and p["rel_err"] is not None]
    empty = [bool(r["chain"]["named"]) for r in rows if not r["effects"]]
    spurious = [bool(r["chain"]["spurious"]) for r in rows if r["effects"]]
    hb = [r["hbridge_chosen"] == r["hbridge"] for r in rows]
    frac = (lambda v: (sum(v) / len(v) if v else float("nan"), len(v)))  # noqa: E731
    return {"named_hi": frac(hi), "median_error": (float(np.median(errs)) if errs else float("nan"), len(errs)),
            "false_claims": frac(empty), "spurious": frac(spurious), "hbridge_right": frac(hb),
            "gap_ratio": (float(np.median([r["chain"]["gap_after"] / r["chain"]["gap_before"] for r in rows])),
                          len(rows)),
            "glitch_listed": frac([r["glitches"] > 0 for r in rows])}


def report(rows: list[dict]) -> str:
    from simrunner.workflows.gap.synth import RANGES

    f = figures(rows)
    lines = [f"{'trial':>5}  {'hidden (truth)':<44} {'H-bridge':<14} {'named (fitted)':<44} gap after/before"]
    for r in sorted(rows, key=lambda r: r["trial"]):
        hidden = ", ".join(f"{e} {r['values'][RANGES[e][0]]:.3g} (SNR {r['snr'].get(e, 0.0):.1f})"
                           for e in r["effects"]) or "none"
        named = ", ".join(f"{n} {r['chain']['parameters'][RANGES[n][0]]:.3g}" if n in RANGES else n
                          for n in r["chain"]["named"]) or "none"
        lines.append(f"{r['trial']:>5}  {hidden:<44} {r['hbridge']}->{r['hbridge_chosen'] or '?':<7} {named:<44} "
                     f"{r['chain']['gap_after'] / r['chain']['gap_before']:.3f}")
    for key, label in (("named_hi", "named where SNR >= 3"), ("median_error", "median parameter error"),
                       ("false_claims", "false claims (effect-free logs)"), ("spurious", "an extra effect named"),
                       ("hbridge_right", "H-bridge mode right"), ("gap_ratio", "held-out gap after / before"),
                       ("glitch_listed", "logs with a glitch listed")):
        v, n = f[key]
        target = TARGETS.get(key)
        pct = key not in ("gap_ratio",)
        text = f"{v:.0%}" if pct and math.isfinite(v) else f"{v:.3f}"
        if not n:
            text = "n/a"
        elif target is not None:
            ok = v >= target if key == "named_hi" else v <= target
            text += f"  (target {'>=' if key == 'named_hi' else '<='} {target:.0%}: {'yes' if ok else 'no'})"
        lines.append(f"{label:<34} {text}  n={n}")
    return "\n".join(lines)


TARGET_ROWS = (  # (figure key, target text, kind, goal text, met test or None)
    ("named_hi", "named where SNR >= 3", "share", ">= 90 %", lambda v: v >= TARGETS["named_hi"]),
    ("median_error", "median parameter error", "error", "<= 15 %", lambda v: v <= TARGETS["median_error"]),
    ("false_claims", "false claims, effect-free logs", "share", "<= 5 %", lambda v: v <= TARGETS["false_claims"]),
    ("spurious", "an extra effect named", "share", "", None),
    ("hbridge_right", "H-bridge mode right", "share", "", None),
    ("gap_ratio", "median held-out gap after/before", "ratio", "", None),
    ("glitch_listed", "logs with a glitch listed (the car slides)", "share", "", None),
)


def results_data(rows: list[dict], command: str, date: str, commit: str, wall_min: float, jobs: int,
                 note: str = "") -> dict:
    """``bench/results/gap_duty.json``: the figures as target rows (tools/render_bench_tables.py
    renders them into docs/tyres.md) and every trial's row."""
    f = figures(rows)
    trials = f"{min(r['trial'] for r in rows)}-{max(r['trial'] for r in rows)}"
    out = []
    for key, target, kind, goal, test in TARGET_ROWS:
        value, n = f[key]
        ok = math.isfinite(value) and n > 0
        out.append({"mode": "duty + slip tyres", "trials": trials, "target": target, "kind": kind,
                    "value": value if ok else None, "n": n, "detail": "", "goal": goal,
                    "met": (bool(test(value)) if ok else False) if test else None, "run": "duty_slip"})
    return {"format": "nxpcup-bench-results/1", "bench": "gap_duty",
            "about": "bench/bench_gap_duty.py's figures (docs/tyres.md); rendered by tools/render_bench_tables.py",
            "runs": {"duty_slip": {"command": command, "date": date, "commit": commit, "wall_min": round(wall_min),
                                   "jobs": jobs, "note": note}},
            "rows": out, "trials_data": rows}


def merged(old: dict, new: dict) -> dict:
    """``new``'s results with ``old``'s trials that ``new`` did not run again, the figures
    recomputed over all of them; the run's note says which trials came from which commit."""
    fresh = {r["trial"] for r in new["trials_data"]}
    rows = sorted([r for r in old.get("trials_data", []) if r["trial"] not in fresh] + new["trials_data"],
                  key=lambda r: r["trial"])
    run = dict(new["runs"]["duty_slip"])
    old_commit = next(iter(old.get("runs", {}).values()), {}).get("commit", "?")
    by_commit: dict[str, list[int]] = {}
    for r in rows:
        by_commit.setdefault(r.get("commit", old_commit), []).append(r["trial"])
    run["note"] = "; ".join(filter(None, [run.get("note"), "trials by commit: " + "; ".join(
        f"{c}: {','.join(map(str, ks))}" for c, ks in by_commit.items())]))
    out = results_data(rows, run["command"], run["date"], run["commit"], run["wall_min"], run["jobs"], run["note"])
    return out


def main(argv: list[str] | None = None) -> None:  # pragma: no cover - a bench
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=12)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--only", default=None, metavar="K,K,...", help="run these trials instead")
    ap.add_argument("--null", type=int, default=0, metavar="N",
                    help="run the first N effect-free trials (k = 0, 4, 8, ...) instead: the false-claim figure")
    ap.add_argument("--results", action="store_true",
                    help=f"write {RESULTS} (merged: a trial run again replaces its row, each row keeps its commit)")
    a = ap.parse_args(argv)
    ks = (list(range(0, 4 * a.null, 4)) if a.null else [int(k) for k in a.only.split(",")] if a.only
          else list(range(a.first, a.first + a.trials)))
    t0 = time.perf_counter()
    rows = []
    with ProcessPoolExecutor(max_workers=a.jobs) as pool:
        futures = [pool.submit(trial, k) for k in ks]
        for fut in as_completed(futures):
            rows.append(fut.result())
            print(f"[trial {rows[-1]['trial']} done, {rows[-1]['wall_s']:.0f} s]", flush=True)
    print(report(rows))
    print(f"wall {time.perf_counter() - t0:.0f} s, {a.jobs} processes")
    if a.results:
        import datetime
        import subprocess

        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=Path(__file__).parent).stdout.strip()
        for r in rows:
            r["commit"] = commit
        command = "python -m bench.bench_gap_duty " + " ".join(argv if argv is not None else sys.argv[1:])
        data = results_data(rows, command, str(datetime.date.today()), commit, (time.perf_counter() - t0) / 60.0,
                            a.jobs)
        if RESULTS.exists():
            data = merged(json.loads(RESULTS.read_text()), data)
        RESULTS.write_text(json.dumps(data, indent=1, default=float) + "\n")


if __name__ == "__main__":  # pragma: no cover
    main()
