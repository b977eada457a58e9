"""Calibrate the acceptance thresholds of :mod:`simrunner.workflows.gap.fit` on effect-free logs.

``python -m simrunner.workflows.gap.thresholds [--logs N] [--seed S] [--jobs J]`` makes ``N``
effect-free synthetic logs (:func:`simrunner.workflows.gap.synth.make_measured_log` with
``effect=None``: noise, nuisance mass/friction, 1 ms physics), runs the whole catalogue on
each (nothing accepted) and prints, for the first chain step's best refitted candidate, its
``delta_bic``, fit ``improvement`` and held-out improvement per log, then the thresholds:
``settings.safety`` times the largest value seen, but not below the floors
(``settings.floor_delta_bic``, ``settings.floor_improvement``, ``settings.floor_held_improvement``). The
values in force are :data:`simrunner.workflows.gap.settings.SETTINGS`'s ``delta_bic_min``,
``improvement_min`` and ``held_improvement_min``: the printed ones, or an override whose reason
is stated there, at the value. It also prints how they compare.
"""
from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from simrunner.workflows.gap.settings import SETTINGS, GapSettings

def _one(args) -> tuple[float, float, float, str]:
    seed, k, settings = args
    from simrunner.workflows.gap.fit import _quiet_worker
    from simrunner.workflows.gap.workflow import run_gap
    from simrunner.workflows.gap.synth import make_measured_log

    _quiet_worker()
    log, _ = make_measured_log(None, rng=np.random.default_rng([seed, k]))
    step = run_gap(log, jobs=1, delta_bic_min=np.inf, max_effects=1, settings=settings).chain.steps[0]
    best = max(step.trials, key=lambda tr: tr.delta_bic)
    held = 1.0 - best.held_gap / step.held_gap_before if step.held_gap_before > 0 else 0.0
    return best.delta_bic, best.improvement, held, best.effect


def calibrate_thresholds(n_logs: int = 10, seed: int = 2024, jobs: int = 2, *,
                         settings: GapSettings = SETTINGS) -> dict:
    """Run ``n_logs`` effect-free logs; return ``{"delta_bic_min", "improvement_min",
    "held_improvement_min", "observed": [(delta_bic, improvement, held_improvement, effect), ...]}``."""
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        observed = list(pool.map(_one, [(seed, k, settings) for k in range(n_logs)]))
    d = max(o[0] for o in observed)
    i = max(o[1] for o in observed)
    h = max(o[2] for o in observed)
    return {"delta_bic_min": max(settings.floor_delta_bic, settings.safety * d),
            "improvement_min": max(settings.floor_improvement, settings.safety * i),
            "held_improvement_min": max(settings.floor_held_improvement, settings.safety * h), "observed": observed}


def main(argv: list[str] | None = None) -> None:  # pragma: no cover - developer tool
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=10)
    ap.add_argument("--seed", type=int, default=2024)
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args(argv)
    res = calibrate_thresholds(a.logs, a.seed, a.jobs)
    for k, (d, i, h, e) in enumerate(res["observed"]):
        print(f"log {k:3d}: best {e:<20} delta_bic {d:8.1f}  improvement {i:7.2%}  held-out {h:7.2%}")
    for key in ("delta_bic_min", "improvement_min", "held_improvement_min"):
        print(f"{key} = {res[key]:.4g}   (in force: {getattr(SETTINGS, key):.4g}, simrunner/workflows/gap/settings.py)")


if __name__ == "__main__":  # pragma: no cover
    main()
