"""The whole gap workflow (``run_gap``) and its output folder (``write_outputs``).

``run_gap`` replays the log with the nominal car, localises the residuals by regime, fits
every catalogue effect (:mod:`simrunner.workflows.gap.fit`), adds the accepted one to the car, and
measures the gap on the held-out windows before and after. ``write_outputs`` writes

    DIR/report.json               effect, parameters, rmse_before/after, ranking, regime stats
    DIR/car.toml                  the car description with the effect added (vehicle.description)
    DIR/gap_before_after.png      measured vs simulated, nominal and fitted model
    DIR/residuals_by_regime.png   residual RMSE and bias per regime, before and after
    DIR/residuals.txt             the regime tables as text

into a temporary sibling folder and renames it into place, so DIR is complete or absent.
"""
from __future__ import annotations

import json
import math
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from simrunner.run.log import RunLog
from simrunner.workflows.gap import GapError
from simrunner.workflows.gap.fit import (CANDIDATES, DELTA_BIC_MIN, IMPROVEMENT_MIN, FitResult, Problem, bic, choose,
                               cost_of, fit_all, nominal_scales, with_effect)
from simrunner.workflows.gap.logs import Derived, check_measured, derive
from simrunner.workflows.gap.regimes import residual_stats, segment
from simrunner.workflows.gap.replay import (FIT_SIGNALS, REPORT_SIGNALS, WINDOW_S, WORKFLOW_DT_S, Prediction, SimFactory, Window,
                                  default_sim_factory, make_windows, noise_rms, replay, residuals, rmse,
                                  smoothed_log, split_windows, window_mask)
from vehicle.description import CarDescription

FORMAT = "nxpcup-gap/1"


@dataclass
class GapResult:
    """Outcome of :func:`run_gap`. ``effect`` is a catalogue name or ``"none"``;
    ``rmse_before``/``rmse_after`` are per signal of REPORT_SIGNALS on held-out windows,
    against the measured log; ``rmse_smoothed_*`` the same against the smoothed measured
    states (the model error without most of the sensor noise, whose size ``noise_rms``
    estimates)."""

    effect: str
    parameters: dict[str, float]
    car: CarDescription
    ranking: list[FitResult]
    nominal_cost: float
    nominal_bic: float
    rmse_before: dict[str, float]
    rmse_after: dict[str, float]
    gap_before: float  # held-out mean squared normalised residual (fit signals and scales)
    gap_after: float
    stats_before: list[dict]
    stats_after: list[dict]
    log: RunLog = field(repr=False)
    derived: Derived = field(repr=False)
    fit_windows: list[Window] = field(repr=False)
    held_windows: list[Window] = field(repr=False)
    pred_before: Prediction = field(repr=False)
    pred_after: Prediction = field(repr=False)
    settings: dict = field(default_factory=dict)
    rmse_smoothed_before: dict[str, float] = field(default_factory=dict)
    rmse_smoothed_after: dict[str, float] = field(default_factory=dict)
    noise_rms: dict[str, float] = field(default_factory=dict)

    @property
    def held_out_worse(self) -> bool:
        """True when an effect was named but the held-out gap (normalised residuals, all
        fit signals) grew: the held-out data do not confirm it (weak or wrong effect)."""
        return self.effect != "none" and self.gap_after > self.gap_before

    def to_json(self) -> dict:
        ratio = {s: (self.rmse_after[s] / self.rmse_before[s] if self.rmse_before[s] > 0 else float("nan"))
                 for s in self.rmse_before}
        return _finite({
            "format": FORMAT, "log": self.log.source, "effect": self.effect, "parameters": self.parameters,
            "rmse_before": self.rmse_before, "rmse_after": self.rmse_after, "rmse_ratio": ratio,
            "rmse_smoothed_before": self.rmse_smoothed_before, "rmse_smoothed_after": self.rmse_smoothed_after,
            "noise_rms": self.noise_rms,
            "gap_before": self.gap_before, "gap_after": self.gap_after, "held_out_worse": self.held_out_worse,
            "nominal": {"cost": self.nominal_cost, "bic": self.nominal_bic},
            "thresholds": {"delta_bic_min": self.settings.get("delta_bic_min"),
                           "improvement_min": self.settings.get("improvement_min")},
            "criterion": "BIC on normalised residuals (lower is better; see simrunner.workflows.gap.fit)",
            "ranking": [r.to_json() for r in self.ranking],
            "windows": {"fit": len(self.fit_windows), "held_out": len(self.held_windows),
                        "window_s": self.settings.get("window_s")},
            "settings": self.settings,
            "regimes_before": self.stats_before, "regimes_after": self.stats_after,
        })


def _finite(obj):
    """JSON has no NaN/inf: map them to null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def run_gap(log: RunLog, car: CarDescription | None = None, *, jobs: int = 2,
            effects: Sequence[str] | None = None, dt_s: float = WORKFLOW_DT_S, window_s: float = WINDOW_S,
            sim_factory: SimFactory = default_sim_factory,
            delta_bic_min: float = DELTA_BIC_MIN, improvement_min: float = IMPROVEMENT_MIN,
            progress: Callable[[str], None] | None = None) -> GapResult:
    """Run the workflow of the module docstring on ``log`` (``car`` default: the default car).

    ``log`` must pass :func:`simrunner.workflows.gap.logs.check_measured` (else
    :class:`simrunner.run.log.LogError`). ``effects`` restricts the candidates (default: the
    whole catalogue); ``progress(label)`` is called after each of the :func:`progress_total`
    stages.
    """
    check_measured(log)
    car = car or CarDescription()
    tick = progress or (lambda label: None)
    derived = derive(log, car.chassis.wheelbase_m, car.steering.limit_rad)
    windows = make_windows(log, window_s)
    masks = segment(log, derived)
    fit_w, held_w = split_windows(windows, strata=[bool(masks["coasting"][w.start:w.stop].any()) for w in windows])
    if len(fit_w) < 2 or not held_w:
        raise GapError(f"{log.source}: expected a log of at least 3 windows of {window_s:g} s "
                       f"(got {len(windows)})")
    pred0 = replay(car, log, derived, windows, dt_s=dt_s, sim_factory=sim_factory)
    res0 = residuals(log, derived, pred0)
    tick("nominal")
    problem = Problem(car, log, derived, tuple(fit_w), nominal_scales(log, res0, fit_w), dt_s, sim_factory)
    nominal_cost = cost_of(problem, car)
    tick("nominal cost")
    ranking = fit_all(problem, nominal_cost, effects, jobs=jobs, progress=tick)
    winner = choose(ranking, delta_bic_min, improvement_min)
    if winner is None:
        car_after, pred1 = car, pred0
    else:
        name, value = winner.effect, next(iter(winner.parameters.values()))
        car_after = with_effect(car, name, value)
        pred1 = replay(car_after, log, derived, windows, dt_s=dt_s, sim_factory=sim_factory)
    tick("held-out check")
    res1 = residuals(log, derived, pred1)
    held = window_mask(len(log), held_w)
    smooth = smoothed_log(log, derived)
    settings = {"dt_s": dt_s, "window_s": window_s, "jobs": jobs, "delta_bic_min": delta_bic_min,
                "improvement_min": improvement_min, "scales": problem.scales,
                "effects": list(effects) if effects is not None else list(CANDIDATES)}
    return GapResult(
        effect=winner.effect if winner else "none", parameters=dict(winner.parameters) if winner else {},
        car=car_after, ranking=ranking, nominal_cost=nominal_cost, nominal_bic=bic(problem, nominal_cost, 0),
        rmse_before=rmse(res0, held), rmse_after=rmse(res1, held),
        gap_before=_gap(res0, held, problem.scales), gap_after=_gap(res1, held, problem.scales),
        stats_before=residual_stats({s: res0[s] for s in REPORT_SIGNALS + ("along_m", "cross_m")}, masks),
        stats_after=residual_stats({s: res1[s] for s in REPORT_SIGNALS + ("along_m", "cross_m")}, masks),
        log=log, derived=derived, fit_windows=fit_w, held_windows=held_w, pred_before=pred0, pred_after=pred1,
        settings=settings,
        rmse_smoothed_before=rmse(residuals(smooth, derived, pred0), held),
        rmse_smoothed_after=rmse(residuals(smooth, derived, pred1), held), noise_rms=noise_rms(log, derived))


def _gap(res: dict[str, np.ndarray], mask: np.ndarray, scales: dict[str, float]) -> float:
    """Mean squared normalised residual over ``mask`` and the fit signals (1 = as large as
    the nominal model's residual on the fit windows)."""
    v = np.concatenate([res[s][mask] / scales[s] for s in FIT_SIGNALS])
    v = v[np.isfinite(v)]
    return float(np.mean(v * v)) if v.size else float("nan")


def progress_total(n_effects: int) -> int:
    """Number of ``progress`` calls of :func:`run_gap` with ``n_effects`` candidates."""
    from simrunner.workflows.gap.fit import REFINE_TOP

    return 3 + n_effects + min(REFINE_TOP, n_effects)


def summary_text(result: GapResult) -> str:
    """Human-readable summary: the regime table (nominal), the ranking, the verdict."""
    from simrunner.workflows.gap.regimes import format_stats

    lines = ["Residuals of the nominal model by regime (all windows):",
             format_stats([r for r in result.stats_before if r["count"]]), "",
             f"{'effect':<22}{'parameter':<32}{'value':>10}{'improvement':>13}{'delta_BIC':>11}"]
    for r in result.ranking:
        (p, v), = r.parameters.items()
        lines.append(f"{r.effect:<22}{p:<32}{v:>10.4g}{r.improvement:>12.1%}{r.delta_bic:>11.1f}")
    lines.append("")
    lines.append(f"missing effect: {result.effect}" + (
        "" if result.effect == "none" else f" ({', '.join(f'{k} = {v:.4g}' for k, v in result.parameters.items())})"))
    lines.append(f"held-out gap (mean squared normalised residual) before -> after: "
                 f"{result.gap_before:.3g} -> {result.gap_after:.3g}")
    if result.held_out_worse:
        lines.append(f"WARNING: the held-out windows do not confirm {result.effect} (their gap grew): the "
                     "evidence comes from the fitted windows only, so the effect is weak or a different "
                     "one. Treat car.toml as uncertain; log the plan again and check.")
    lines.append("held-out RMSE before -> after: " + ", ".join(
        f"{s} {result.rmse_before[s]:.4g} -> {result.rmse_after[s]:.4g}" for s in REPORT_SIGNALS))
    if result.rmse_smoothed_before:
        lines.append("  against the smoothed measured states: " + ", ".join(
            f"{s} {result.rmse_smoothed_before[s]:.4g} -> {result.rmse_smoothed_after[s]:.4g}"
            for s in REPORT_SIGNALS))
        lines.append("  estimated sensor noise (measured - smoothed, RMS): " + ", ".join(
            f"{s} {v:.3g}" for s, v in result.noise_rms.items() if math.isfinite(v)))
    return "\n".join(lines)


def write_outputs(result: GapResult, out_dir: str | Path, *, force: bool = False) -> Path:
    """Write the output folder atomically (see the module docstring); returns its path.

    An existing ``out_dir`` is replaced only with ``force``; otherwise GapError.
    """
    from simrunner.workflows.gap.plots import plot_before_after, plot_regimes

    out = Path(out_dir)
    if out.exists() and not force:
        raise GapError(f"{out}: output folder exists (use --force to replace it)")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        (tmp / "report.json").write_text(json.dumps(result.to_json(), indent=2) + "\n")
        result.car.save(tmp / "car.toml")
        (tmp / "residuals.txt").write_text(summary_text(result) + "\n")
        plot_before_after(result, tmp / "gap_before_after.png")
        plot_regimes(result, tmp / "residuals_by_regime.png")
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old.", dir=out.parent))
            out.rename(old / out.name)
            tmp.rename(out)
            shutil.rmtree(old)
        else:
            tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out

