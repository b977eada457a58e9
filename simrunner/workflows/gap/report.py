"""The answer of the gap workflow: :class:`GapResult` (what :func:`simrunner.workflows.gap.workflow.run_gap`
returns), its text (:func:`summary_text`) and its output folder (:func:`write_outputs`):

    DIR/report.json               the chain, parameters, rmse_before/after, glitches, leftovers, regimes
    DIR/car.toml                  the car description with every kept effect (vehicle.description)
    DIR/gap_before_after.png      measured vs simulated, nominal and final model (first log)
    DIR/residuals_by_regime.png   residual RMSE and bias per regime, before and after
    DIR/residuals.txt             the answer, then the regime tables, as text
    DIR/findings.txt              what was found as it was found (simrunner.workflows.gap.live)

written into a temporary sibling folder and swapped into place (trackgen.outdir). While a run
goes on, DIR holds only ``findings.txt``, a line per finding as it comes
(:func:`start_live_folder`); a run stopped before its end (Ctrl-C, SIGTERM) leaves the partial
report of :func:`write_partial` (``report.json`` with ``"status": "partial"``, the model of the
finished steps in ``car.toml``, ``residuals.txt``, ``findings.txt``).
"""
from __future__ import annotations

import contextlib
import json
import math
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from simrunner.telemetry.log import RunLog
from simrunner.workflows.gap import GapError
from simrunner.workflows.gap.chain import Chain, with_parameters
from simrunner.workflows.gap.fit import CANDIDATES, FitResult
from simrunner.workflows.gap.glitches import Glitch
from simrunner.workflows.gap.live import Findings
from simrunner.workflows.gap.logs import Derived
from simrunner.workflows.gap.replay import Prediction, Window
from simrunner.workflows.gap.settings import SETTINGS, GapSettings
from trackgen.outdir import clean_stale, make_temp, swapped_in
from vehicle.description import CarDescription

FORMAT = "nxpcup-gap/2"
# a log whose stamps start this far from 0 (epoch or ROS time) gets its glitch times also as
# seconds into the log in residuals.txt
@dataclass(frozen=True)
class LogPart:
    """One log of the data set as the workflow used it."""

    log: RunLog
    derived: Derived
    glitches: tuple[Glitch, ...]
    fit_windows: tuple[Window, ...]
    held_windows: tuple[Window, ...]
    signals: tuple[str, ...]
    unchecked: tuple[str, ...] = ()  # conventions the log shows too little of (check_conventions)

    @property
    def windows(self) -> tuple[Window, ...]:
        return tuple(sorted(self.fit_windows + self.held_windows, key=lambda w: w.start))


@dataclass
class GapResult:
    """Outcome of :func:`simrunner.workflows.gap.workflow.run_gap`. ``effects``: the kept effects in
    the order chosen (``[]``:
    none); ``effect`` the same joined by ``+`` (or ``"none"``); ``parameters`` every kept
    parameter; ``rmse_before``/``rmse_after`` per signal of REPORT_SIGNALS on the held-out
    windows of every log, against the measured logs; ``rmse_smoothed_*`` the same against
    the smoothed measured states (the model error without most of the sensor noise, whose
    size ``noise_rms`` estimates). ``log``, ``derived``, ``pred_*`` and the windows are those
    of the first log (plots)."""

    effects: list[str]
    parameters: dict[str, float]
    car: CarDescription
    chain: Chain
    ranking: list[FitResult]  # the first step's screening of every candidate
    nominal_cost: float
    nominal_bic: float
    rmse_before: dict[str, float]
    rmse_after: dict[str, float]
    gap_before: float  # held-out gap: robust mean squared normalised residual (fit signals and scales)
    gap_after: float
    stats_before: list[dict]
    stats_after: list[dict]
    parts: list[LogPart] = field(repr=False)
    pred_before: Prediction = field(repr=False)
    pred_after: Prediction = field(repr=False)
    settings: dict = field(default_factory=dict)
    rmse_smoothed_before: dict[str, float] = field(default_factory=dict)
    rmse_smoothed_after: dict[str, float] = field(default_factory=dict)
    noise_rms: dict[str, float] = field(default_factory=dict)
    unrevealable: dict[str, list[str]] = field(default_factory=dict)  # effect -> signals (or manoeuvre) it needs
    leftovers: list[dict] = field(default_factory=list)
    gap_ls_before: float = math.nan  # the same in plain least squares (every window at full weight)
    gap_ls_after: float = math.nan
    # standard error of each kept parameter (simrunner.workflows.gap.uncertainty; nan: not pinned)
    parameter_sigma: dict[str, float] = field(default_factory=dict)
    # kept parameters that one fit window alone pins (their sigma nan): (log source, t_start_s, t_end_s)
    parameter_one_window: dict[str, tuple[str, float, float]] = field(default_factory=dict)
    # kept parameters the fit windows pin only to an interval (chain.Chain.spans): (low, high);
    # the value kept is its middle
    parameter_spans: dict[str, tuple[float, float]] = field(default_factory=dict)
    # per log with held-out windows: log, held_windows, gap_before/after, rmse_before/after
    per_log: list[dict] = field(default_factory=list)
    # the thresholds of the run (the report's wording uses some of them)
    gap_settings: GapSettings = SETTINGS
    # catalogue effects not tried because the car cannot have them: effect -> what it needs
    not_applicable: dict[str, str] = field(default_factory=dict)

    @property
    def effect(self) -> str:
        return "+".join(self.effects) if self.effects else "none"

    @property
    def runs(self) -> dict:
        """The data set counted in runs (logs): split into fit and held-out windows, fitted
        whole, held out whole (short runs pooled, ``workflow.pool_short_runs``), and seconds."""
        def seconds(p, windows):
            t = p.log.t_s
            return sum(float(t[w.stop - 1] - t[w.start]) for w in windows)
        return {"runs": len(self.parts),
                "split": sum(1 for p in self.parts if p.fit_windows and p.held_windows),
                "fitted_whole": sum(1 for p in self.parts if p.fit_windows and not p.held_windows),
                "held_out_whole": sum(1 for p in self.parts if p.held_windows and not p.fit_windows),
                "unused": sum(1 for p in self.parts if not p.windows),
                "fit_s": sum(seconds(p, p.fit_windows) for p in self.parts),
                "held_out_s": sum(seconds(p, p.held_windows) for p in self.parts)}

    @property
    def log(self) -> RunLog:
        return self.parts[0].log

    @property
    def derived(self) -> Derived:
        return self.parts[0].derived

    @property
    def fit_windows(self) -> list[Window]:
        return list(self.parts[0].fit_windows)

    @property
    def held_windows(self) -> list[Window]:
        return list(self.parts[0].held_windows)

    @property
    def glitches(self) -> list[tuple[str, Glitch]]:
        return [(p.log.source, g) for p in self.parts for g in p.glitches]

    @property
    def at_bounds(self) -> list[str]:
        """Kept parameters at (within 1 % of) an end of their fit range: the fit wanted to go
        further, so the catalogue probably lacks the real cause (or the car file is far off)."""
        by_field = {c.field: c for c in CANDIDATES.values()}
        return [name for name, v in self.parameters.items() if by_field[name].at_bound(v, self.gap_settings)]

    @property
    def logs_worse(self) -> list[str]:
        """The logs (of several) whose held-out gap the kept effects made larger: the one
        model does not fit them all (a speed limit, a battery, a floor changed between them)."""
        if len(self.per_log) < 2 or not self.effects:
            return []
        return [d["log"] for d in self.per_log if d["gap_after"] > d["gap_before"]]

    @property
    def signals_worse(self) -> dict[str, float]:
        """:func:`worse_signals` of the held-out RMSEs when effects were kept (signal ->
        RMSE after / before)."""
        return (worse_signals(self.rmse_before, self.rmse_after, self.gap_settings.held_improvement_min)
                if self.effects else {})

    @property
    def held_out_worse(self) -> bool:
        """True when effects were kept but the held-out gap grew (cannot happen for a chain
        whose every step was confirmed on held-out data; kept as a safety flag)."""
        return bool(self.effects) and self.gap_after > self.gap_before

    def to_json(self) -> dict:
        ratio = {s: (self.rmse_after[s] / self.rmse_before[s] if self.rmse_before.get(s) else float("nan"))
                 for s in self.rmse_before}
        return _finite({
            "format": FORMAT, "logs": [p.log.source for p in self.parts], "log": self.log.source,
            "effects": self.effects, "effect": self.effect, "parameters": self.parameters,
            "parameter_sigma": self.parameter_sigma,
            "parameter_one_window": {k: {"log": src, "t_start_s": t0, "t_end_s": t1}
                                     for k, (src, t0, t1) in self.parameter_one_window.items()},
            "parameter_spans": {k: list(v) for k, v in self.parameter_spans.items()},
            "per_log": self.per_log, "logs_worse": self.logs_worse, "runs": self.runs,
            "gap_before": self.gap_before, "gap_after": self.gap_after,
            "gap_ls_before": self.gap_ls_before, "gap_ls_after": self.gap_ls_after,
            "rmse_before": self.rmse_before, "rmse_after": self.rmse_after, "rmse_ratio": ratio,
            "rmse_smoothed_before": self.rmse_smoothed_before, "rmse_smoothed_after": self.rmse_smoothed_after,
            "noise_rms": self.noise_rms, "held_out_worse": self.held_out_worse,
            "signals_worse": self.signals_worse, "at_bounds": self.at_bounds,
            "chain": self.chain.to_json(), "chain_stop": self.chain.stop_reason,
            "rejected": [{"step": k, "effect": t.effect, "parameters": t.parameters, "reason": t.reason}
                         for k, t in self.chain.rejected],
            "swaps": [sw.to_json() for sw in self.chain.swaps],
            "pruned": [{"effect": t.effect, "parameters": t.parameters, "reason": t.reason,
                        "delta_bic": t.delta_bic, "improvement": t.improvement, "after_step": after}
                       for t, after in zip(self.chain.pruned, self.chain.pruned_after)],
            "unexplained": self.leftovers,
            "cannot_reveal": self.unrevealable, "not_applicable": self.not_applicable,
            "settings_changed": self.gap_settings.changed(),
            "conventions_unchecked": {p.log.source: list(p.unchecked) for p in self.parts if p.unchecked},
            "glitches": [{"log": src, "kind": g.kind, "t_start_s": g.t_start_s, "t_end_s": g.t_end_s,
                          "column": g.column, "detail": g.detail} for src, g in self.glitches],
            "signals": list(self.settings.get("signals", ())),
            "nominal": {"cost": self.nominal_cost, "bic": self.nominal_bic},
            "thresholds": {"delta_bic_min": self.settings.get("delta_bic_min"),
                           "improvement_min": self.settings.get("improvement_min"),
                           "held_improvement_min": self.settings.get("held_improvement_min")},
            "criterion": "BIC on normalised residuals (lower is better; see simrunner.workflows.gap.fit)",
            "ranking": [r.to_json() for r in self.ranking],
            "windows": {"fit": sum(len(p.fit_windows) for p in self.parts),
                        "held_out": sum(len(p.held_windows) for p in self.parts),
                        "window_s": self.settings.get("window_s")},
            "settings": self.settings,
            "regimes_before": self.stats_before, "regimes_after": self.stats_after,
        })


def worse_signals(before: dict[str, float], after: dict[str, float],
                  held_improvement_min: float = SETTINGS.held_improvement_min) -> dict[str, float]:
    """The signals whose RMSE ``after`` exceeds ``before`` by more than the held-out test's
    noise level (the mean square up by ``held_improvement_min``, the smallest held-out gain
    the chain takes for an effect): ``{signal: after / before}``. The chain keeps effects
    that shrink the held-out gap over all signals; one that shrinks it while a signal gets
    worse trades that signal for the others, the mark of a stand-in (a sloped floor's
    coasting fitted as drag: speed and position worse, heading better)."""
    limit = math.sqrt(1.0 + held_improvement_min)
    return {s: after[s] / b for s, b in before.items()
            if b > 0 and math.isfinite(b) and math.isfinite(after.get(s, math.nan)) and after[s] > b * limit}


def _finite(obj):
    """JSON has no NaN/inf: map them to null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def _params_text(params: dict[str, float], sigma: dict[str, float] | None = None,
                 spans: dict[str, tuple[float, float]] | None = None,
                 one_window: dict[str, tuple[str, float, float]] | None = None,
                 at_bounds: Sequence[str] = ()) -> str:
    sigma, spans, one_window = sigma or {}, spans or {}, one_window or {}

    def one(k: str, v: float) -> str:
        if k in spans:
            return (f"{k} = {v:.4g} (any value {spans[k][0]:.4g}-{spans[k][1]:.4g} fits the fit windows as well: "
                    "they hold nothing that pins it closer; the middle is kept)")
        if math.isfinite(sigma.get(k, math.nan)):
            return f"{k} = {v:.4g} +- {sigma[k]:.2g}"
        if k in at_bounds and k in sigma:
            return f"{k} = {v:.4g} (+- not known: at the end of its fit range, see the warning below)"
        if k in one_window:
            src, t0, t1 = one_window[k]
            return (f"{k} = {v:.4g} (+- not known: one window alone pins it, {Path(src).name} {t0:.1f}-{t1:.1f} s; "
                    "a log with more of that driving would tell how well)")
        return f"{k} = {v:.4g}" + (" (+- not known: the log does not pin it)" if k in sigma else "")

    return ", ".join(one(k, v) for k, v in params.items())


def summary_text(result: GapResult) -> str:
    """Human-readable summary: the answer first (the chain, the held-out figures, what is left
    unexplained), then the screening of the first step and the regime tables."""
    from simrunner.workflows.gap.regimes import format_stats

    settings = result.gap_settings
    chain = result.chain
    lines = [f"effects found: {', '.join(result.effects) if result.effects else 'none'}"]
    if result.parameters:
        text = _params_text(result.parameters, result.parameter_sigma, result.parameter_spans,
                            result.parameter_one_window, result.at_bounds)
        lines.append(f"  parameters: {text}")
        if result.parameter_sigma:
            lines.append("  (+- one standard error from the fits that leave one fit window out, the fit's distance "
                         "from the cost's minimum and the physics step's bias: a lower bound; a stand-in effect or "
                         "a wrong car-file number is not in it)")
    for step in chain.steps:  # a look-alike kept as well (at a later step) is no alternative
        alike = [a.effect for a in step.alike if a.effect not in result.effects]
        if alike and step.kept is not None and step.kept.effect in result.effects:
            others = " or ".join(alike)
            lines.append(f"  {step.kept.effect} or {others}: these logs cannot tell them apart (step {step.index}: "
                         f"window by window, within {result.gap_settings.alike_z:g} standard errors; "
                         "treat the name as one of these)")
    fastest = max((float(np.nanmax(np.abs(p.derived.speed_mps))) for p in result.parts
                   if np.isfinite(p.derived.speed_mps).any()), default=0.0)
    if fastest > settings.top_speed_margin * result.car.drive.max_speed_mps:
        lines.append(f"  WARNING: the logs reach {fastest:.3g} m/s, beyond the car file's top speed "
                     f"({result.car.drive.max_speed_mps:g} m/s, car \"{result.car.name}\"): is this the car's "
                     "file (--car CAR.toml)? Every effect is fitted against its numbers")
    for name in result.at_bounds:
        lines.append(f"  WARNING: {name} = {result.parameters[name]:.4g} is at the end of its fit range: the "
                     "real cause is probably outside the catalogue (or the car file is far off); "
                     "treat this value as a stand-in")
    lines.append(f"held-out gap (mean squared normalised residual, robust) before -> after: "
                 f"{result.gap_before:.3g} -> {result.gap_after:.3g}"
                 + (f"  (least squares: {result.gap_ls_before:.3g} -> {result.gap_ls_after:.3g})"
                    if math.isfinite(result.settings.get("robust_scale", math.inf)) else ""))
    gone = {t.effect: after for t, after in zip(chain.pruned, chain.pruned_after)}
    for step in chain.steps:
        kept = step.kept
        if kept is not None:
            lines.append(f"  step {step.index}: + {kept.effect:<20} held-out gap {step.gap_before:.3g} -> "
                         f"{step.gap_after:.3g}  (delta_BIC {kept.delta_bic:.0f}, fit {kept.improvement:.1%})"
                         + (f"  removed by the check after step {gone[kept.effect]}" if kept.effect in gone else ""))
            for a in step.alike:
                lines.append(f"          as good on these windows: {a.effect:<20} (per-window cost difference "
                             f"z = {a.z:+.2f} over {a.windows} windows)")
        for sw in (sw for sw in chain.swaps if sw.step == step.index):
            lines.append(f"  after step {sw.step}: {sw.out} -> {sw.into} (exchanged, all refitted): fit cost "
                         f"{sw.cost_before:.4g} -> {sw.cost_after:.4g}, held-out gap {sw.held_gap_before:.3g} -> "
                         f"{sw.held_gap_after:.3g}"
                         + (f"; removed by the check after step {gone[sw.into]}" if sw.into in gone else ""))
    lines.append(f"  the chain stopped: {chain.stop_reason}")
    screened, fitted = result.settings.get("screen_windows_s"), result.settings.get("fit_windows_s")
    if screened is not None and fitted is not None and screened < fitted:
        lines.append(f"  screened and refitted on {screened:.0f} s of the {fitted:.0f} s of fit windows (a subset by "
                     "regime; `--screen 0` uses them all: slower, and a near tie between look-alike effects then "
                     "depends less on which windows the layout and any glitch leave)")
    for tr, after in zip(chain.pruned, chain.pruned_after):
        lines.append(f"  check after step {after}: - {tr.effect:<18} without it, the others refitted: {tr.reason}")
    if chain.rejected:
        lines.append("tried and not kept:")
        for k, tr in chain.rejected:
            lines.append(f"  step {k}: {tr.effect:<20} {tr.reason}")
    hb = result.settings.get("hbridge")
    if hb:
        costs = ", ".join(f"{m} {c:.4g}" for m, c in hb["held_cost"].items())
        lines.append(f"H-bridge (drive.hbridge, a duty log): {hb['chosen']}"
                     + (f" (the car file says {hb['file']})" if hb["chosen"] != hb["file"] else "")
                     + f"; held-out cost {costs}")
    runs = result.runs
    if runs["runs"] > 1:
        whole = [f"{runs[k]} {label}" for k, label in (("split", "split into fit and held-out windows"),
                                                        ("fitted_whole", "fitted whole"),
                                                        ("held_out_whole", "held out whole"),
                                                        ("unused", "without a clean window")) if runs[k]]
        lines.append(f"data: {runs['runs']} runs ({', '.join(whole)}): {runs['fit_s']:.0f} s of fit windows, "
                     f"{runs['held_out_s']:.0f} s held out")
    lines.append("held-out RMSE before -> after: " + ", ".join(
        f"{s} {result.rmse_before[s]:.4g} -> {result.rmse_after[s]:.4g}" for s in result.rmse_before))
    if result.rmse_smoothed_before:
        lines.append("  against the smoothed measured states: " + ", ".join(
            f"{s} {result.rmse_smoothed_before[s]:.4g} -> {result.rmse_smoothed_after[s]:.4g}"
            for s in result.rmse_smoothed_before))
        lines.append("  estimated sensor noise (measured - smoothed, RMS): " + ", ".join(
            f"{s} {v:.3g}" for s, v in result.noise_rms.items() if math.isfinite(v)))
    if result.held_out_worse:
        lines.append("WARNING: the held-out gap grew with the kept effects; treat car.toml as uncertain.")
    if result.signals_worse and not result.held_out_worse:
        lines.append("WARNING: the kept effects make the held-out " + ", ".join(
            f"{s} RMSE {r - 1.0:.0%} larger" for s, r in result.signals_worse.items())
            + ", while the gap over all signals shrinks: they trade these signals for the others, so one of "
            "them may stand in for something the catalogue lacks (docs/gap.md, \"Known limits\").")
    if len(result.per_log) > 1:
        lines.append("held-out gap per log before -> after: " + "; ".join(
            f"{Path(d['log']).name} {d['gap_before']:.3g} -> {d['gap_after']:.3g}" for d in result.per_log))
    for name in result.logs_worse:
        d = next(d for d in result.per_log if d["log"] == name)
        lines.append(f"WARNING: the kept effects fit {Path(name).name} worse than the nominal car (held-out gap "
                     f"{d['gap_before']:.3g} -> {d['gap_after']:.3g}): one model does not fit all these logs. Were "
                     "they driven with one set-up (speed limit, battery, tyres, floor)? Run them one at a time "
                     "to compare.")
    if result.leftovers and not result.settings.get("max_effects", result.gap_settings.max_effects):
        lines.append("above the sensor noise (the nominal model, all windows; no effect was tried: max effects 0):")
        lines += [f"  {d['text']}" for d in result.leftovers[:8]]
    elif result.leftovers:
        lines.append("left unexplained by the catalogue (final model, all windows):")
        lines += [f"  {d['text']}" for d in result.leftovers[:8]]
    elif result.signals_worse and not result.held_out_worse:
        lines.append("left unexplained: nothing well above the sensor noise in any regime, but the kept effects "
                     "trade signals (the warning above): part of the gap may have a cause the catalogue lacks")
    else:
        lines.append("left unexplained: nothing well above the sensor noise")
    for part in (p for p in result.parts if p.unchecked):
        lines.append(f"not checked in {Path(part.log.source).name} (docs/gap.md, \"Input\"): "
                     + "; ".join(part.unchecked) + ": make sure of these by hand")
    if result.not_applicable:
        needs = sorted(set(result.not_applicable.values()))
        lines.append(f"not tried: {', '.join(result.not_applicable)} (they need {' or '.join(needs)})")
    if result.unrevealable:
        lines.append("this log cannot reveal: " + ", ".join(
            f"{n} (needs {' or '.join(s)})" for n, s in result.unrevealable.items()))
    if result.glitches:
        lines.append(f"glitches kept out of the windows ({len(result.glitches)}):")
        starts = {p.log.source: float(p.log.t_s[0]) for p in result.parts}
        for src, g in result.glitches[:settings.glitches_listed]:
            t0 = starts.get(src, 0.0)  # stamps far from 0 (epoch time): also say how far into the log
            into = f" ({g.t_start_s - t0:.1f} s into the log)" if abs(t0) >= settings.epoch_like_s else ""
            lines.append(f"  {Path(src).name} t = {g.t_start_s:.3f}..{g.t_end_s:.3f} s{into}: {g.kind} "
                         f"({g.column}) {g.detail}")
        if len(result.glitches) > settings.glitches_listed:
            lines.append(f"  ... and {len(result.glitches) - settings.glitches_listed} more "
                         "(all of them: report.json, \"glitches\")")
    lines += ["", "first step, every candidate screened (one parameter, the others nominal):"]
    if result.ranking:
        lines.append(f"{'effect':<22}{'parameter':<32}{'value':>10}{'improvement':>13}{'delta_BIC':>11}")
    else:  # not an empty table: no candidate was ranked
        lines.append(f"  none: the chain ended before its first step was done ({chain.stop_reason})")
    for r in result.ranking:
        (p, v), = r.parameters.items()
        lines.append(f"{r.effect:<22}{p:<32}{v:>10.4g}{r.improvement:>12.1%}{r.delta_bic:>11.1f}")
    lines += ["", "Residuals of the nominal model by regime (all windows):",
              format_stats([r for r in result.stats_before if r["count"]]),
              "", "Residuals of the final model by regime (all windows):",
              format_stats([r for r in result.stats_after if r["count"]])]
    return "\n".join(lines)


def car_sources(result: GapResult) -> dict[str, str]:
    """``"effects.field"`` -> where the written car file's kept parameters come from (see
    :meth:`vehicle.description.CarDescription.to_toml`)."""
    logs = ", ".join(Path(p.log.source).name for p in result.parts)
    fitted = (f"fitted by simrunner gap ({result.effect}) on {logs}, held-out gap "
              f"{result.gap_before:.3g} -> {result.gap_after:.3g}")

    def sigma(name: str) -> str:
        if name in result.parameter_spans:
            lo, hi = result.parameter_spans[name]
            return f", pinned only to {lo:.4g}-{hi:.4g} (the middle kept)"
        sd = result.parameter_sigma.get(name, math.nan)
        if name in result.parameter_one_window:
            src, t0, t1 = result.parameter_one_window[name]
            return f", pinned by one window alone ({Path(src).name} {t0:.1f}-{t1:.1f} s)"
        return f", standard error {sd:.2g}" if math.isfinite(sd) else ""

    return {f"effects.{name}": fitted + sigma(name) for name in result.parameters}


def check_output_dir(out_dir: str | Path, *, force: bool = False) -> Path:
    """Raise GapError (one line) unless :func:`write_outputs` can write ``out_dir``: it
    exists without ``force``, or its folder cannot be made or written. Made before a run
    that takes minutes, so that a typo in ``-o`` costs none of them."""
    out = Path(out_dir)
    if out.exists() and not force:
        raise GapError(f"{out}: output folder exists (use --force to replace it)")
    made = [p for p in (out.parent, *out.parent.parents) if not p.exists()]  # the folders the probe makes
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.rmtree(make_temp(out))
    except OSError as exc:
        raise GapError(f"{out}: cannot write the output folder there ({exc.strerror or exc})") from None
    finally:
        for folder in made:  # deepest first: leave nothing behind before the run
            with contextlib.suppress(OSError):
                folder.rmdir()
    return out


@contextlib.contextmanager
def _swapped_in(out: Path):
    """:func:`trackgen.outdir.swapped_in`, a folder that cannot be written a one-line GapError."""
    try:
        with swapped_in(out) as tmp:
            yield tmp
    except OSError as exc:
        raise GapError(f"{out}: cannot write the output folder ({exc.strerror or exc})") from None


def start_live_folder(out_dir: str | Path, *, force: bool = False) -> Path:
    """Make ``out_dir`` the running run's folder (an existing one replaced only with
    ``force``), holding an empty ``findings.txt``; returns that file's path."""
    out = check_output_dir(out_dir, force=force)
    clean_stale(out)
    with _swapped_in(out) as tmp:
        (tmp / "findings.txt").write_text("")
    return out / "findings.txt"


class LiveFolder:
    """``findings.txt`` in the output folder as the findings come (pass :meth:`add` as, or
    from, the :class:`~simrunner.workflows.gap.live.Findings` listener). The folder is made at the
    nominal car's finding, once the input is known good (bad input leaves nothing), with the
    lines found before it; ``started`` says whether it exists."""

    def __init__(self, out_dir: str | Path, *, force: bool = False):
        self.out, self.force = Path(out_dir), force
        self.started = False
        self._early: list[str] = []

    def add(self, finding) -> None:
        if finding.kind == "stage":
            return
        if not self.started and finding.kind in ("nominal", "done"):
            start_live_folder(self.out, force=self.force)
            self.started = True
        if not self.started:
            self._early.append(finding.line())
            return
        try:
            with open(self.out / "findings.txt", "a") as fh:
                fh.write("".join(line + "\n" for line in self._early + [finding.line()]))
            self._early = []
        except OSError as exc:
            raise GapError(f"{self.out}/findings.txt: cannot write ({exc.strerror or exc})") from None


def findings_text(findings: Findings) -> str:
    """``findings.txt``: a line per finding but the stages, ``[m:ss] text``."""
    return "".join(f.line() + "\n" for f in findings.items if f.kind != "stage")


def write_outputs(result: GapResult, out_dir: str | Path, *, force: bool = False,
                  findings: Findings | None = None) -> Path:
    """Write the output folder atomically (see the module docstring); returns its path.

    An existing ``out_dir`` is replaced only with ``force``; that, or a folder that cannot
    be written (the disk full, no permission), is a GapError; nothing is left half-written.
    ``findings``: the run's, written to ``findings.txt``.
    """
    from simrunner.workflows.gap.plots import plot_before_after, plot_regimes

    out = check_output_dir(out_dir, force=force)
    clean_stale(out)
    with _swapped_in(out) as tmp:
        (tmp / "report.json").write_text(json.dumps(result.to_json(), indent=2) + "\n")
        result.car.save(tmp / "car.toml", car_sources(result))
        (tmp / "residuals.txt").write_text(summary_text(result) + "\n")
        plot_before_after(result, tmp / "gap_before_after.png")
        plot_regimes(result, tmp / "residuals_by_regime.png")
        if findings is not None:
            (tmp / "findings.txt").write_text(findings_text(findings))
    return out



def partial_json(findings: Findings, stopped: str) -> dict:
    """``report.json`` of a run stopped before its end: ``"status": "partial"``, why and during
    which stage, the model of the finished steps (not re-checked, no uncertainty) and every
    finding with its figures."""
    return _finite({
        "format": FORMAT, "status": "partial", "stopped": stopped, "stage": findings.stage,
        "elapsed_s": findings.elapsed_s(), "logs": [f.data.get("log") for f in findings.of_kind("log")],
        "effects": findings.effects, "parameters": findings.parameters,
        "nominal_held_gap": next((f.data.get("held_gap") for f in findings.of_kind("nominal")), None),
        "findings": [{"kind": f.kind, "elapsed_s": f.elapsed_s, "text": f.text,
                      **{k: v for k, v in f.data.items() if k != "glitch_list"}} for f in findings.items],
        "glitches": [{"log": src, "kind": g.kind, "t_start_s": g.t_start_s, "t_end_s": g.t_end_s,
                      "column": g.column, "detail": g.detail} for src, g in _found_glitches(findings)],
    })


def _found_glitches(findings: Findings) -> list[tuple[str, Glitch]]:
    """Every glitch of the logs read so far (the log findings' ``glitch_list``), with its log."""
    return [(f.data.get("log"), g) for f in findings.of_kind("log") for g in f.data.get("glitch_list", ())]


def partial_text(findings: Findings, stopped: str) -> str:
    """``residuals.txt`` of a stopped run: what stopped it, the model so far, the findings."""
    m, s = divmod(int(findings.elapsed_s()), 60)
    model = (", ".join(f"{k} = {v:.4g}" for k, v in findings.parameters.items())
             if findings.effects else "none yet (the nominal car)")
    lines = [f"PARTIAL REPORT: {stopped} after {m}:{s:02d}, during {findings.stage}.",
             f"effects kept by the finished steps: {', '.join(findings.effects) or 'none'}",
             f"  parameters: {model}",
             "  (not re-checked by the final check, no uncertainty, no held-out figures of the final model: "
             "run again, with --budget MINUTES to end in time)", "", "findings:"]
    text = "\n".join(lines) + "\n" + findings_text(findings)
    glitches = _found_glitches(findings)
    if glitches:  # the log findings name the first three; here all of them, as the whole report lists them
        listed = SETTINGS.glitches_listed
        text += f"\nglitches kept out of the windows ({len(glitches)}):\n" + "".join(
            f"  {Path(src).name} t = {g.t_start_s:.3f}..{g.t_end_s:.3f} s: {g.kind} ({g.column}) {g.detail}\n"
            for src, g in glitches[:listed])
        if len(glitches) > listed:
            text += f"  ... and {len(glitches) - listed} more (all of them: report.json, \"glitches\")\n"
    return text


def write_partial(findings: Findings, out_dir: str | Path, stopped: str) -> Path:
    """The partial report of a run stopped before its end (module docstring), written over its
    live folder ``out_dir`` as :func:`write_outputs` writes a whole one. ``car.toml`` is the model
    of the finished steps when the run got as far as the nominal car."""
    out = Path(out_dir)
    with _swapped_in(out) as tmp:
        (tmp / "report.json").write_text(json.dumps(partial_json(findings, stopped), indent=2) + "\n")
        (tmp / "residuals.txt").write_text(partial_text(findings, stopped))
        (tmp / "findings.txt").write_text(findings_text(findings))
        if findings.base_car is not None:
            with_parameters(findings.base_car, findings.parameters).save(
                tmp / "car.toml", {f"effects.{k}": "the finished steps of a stopped `simrunner gap` run (partial)"
                                   for k in findings.parameters})
    return out
