"""The gap workflow's entry: :func:`run_gap` (``simrunner gap``'s work, from logs to a
:class:`~simrunner.workflows.gap.report.GapResult`).

``run_gap`` takes one or several logs of one car. Per log (:func:`prepare`): check it, find
its glitches (:mod:`simrunner.workflows.gap.glitches`: kept out of every window), derive
smoothed states, cut windows and split them into fit and held-out windows. Then it replays
the nominal car, builds the chain of effects (:mod:`simrunner.workflows.gap.chain`: forward
selection with joint refits, each kept effect confirmed on the held-out windows), measures
the gap on the held-out windows before and after, the kept parameters' standard errors
(:mod:`simrunner.workflows.gap.uncertainty`), and compares what is left with the sensor noise
per signal and regime (:func:`leftovers`). :mod:`simrunner.workflows.gap.report` writes the
answer. Thresholds: :mod:`simrunner.workflows.gap.settings`.
"""
from __future__ import annotations

import dataclasses
import math
import time
from typing import Callable, Sequence

import numpy as np

from simrunner.telemetry.log import RunLog
from simrunner.workflows.gap import GapError
from simrunner.workflows.gap.chain import build_chain, screening_problem
from simrunner.workflows.gap.fit import (CANDIDATES, Problem, Segment, bic, nominal_scales, robust_scale_of, rescaled,
                                         robust_total, cost_of, window_costs)
from simrunner.workflows.gap.conventions import check_conventions
from simrunner.workflows.gap.glitches import Glitch, find_glitches, glitch_mask
from simrunner.workflows.gap.live import Budget, Findings
from simrunner.workflows.gap.logs import Derived, check_measured, derive, is_duty_log
from simrunner.workflows.gap.regimes import residual_stats, reversal_onsets, segment
from simrunner.workflows.gap.replay import (FIT_SIGNALS, REPORT_SIGNALS, Prediction,
                                            SimFactory, Window, default_sim_factory, make_windows, noise_rms,
                                            replay, residuals, rmse, signals_of, smoothed_log, split_windows,
                                            window_mask)
from simrunner.workflows.gap.report import GapResult, LogPart
from simrunner.workflows.gap.settings import SETTINGS, GapSettings
from simrunner.workflows.gap.uncertainty import parameter_uncertainty
from vehicle.description import CarDescription

def window_strata(log: RunLog, derived: Derived, masks: dict[str, np.ndarray],
                  windows: Sequence[Window], max_brake_mps2: float | None = None, *,
                  settings: GapSettings = SETTINGS) -> list[str]:
    """The group of each window for the fit/held-out split (:func:`split_windows`): the
    rarest manoeuvre it holds. ``"brake_to_reverse"``: a reverse command while the car
    still rolls forward (:func:`simrunner.workflows.gap.regimes.brake_to_reverse`, with the
    car file's ``max_brake_mps2``); else ``"coast"``: coasting or rolling with no drive
    commanded; else ``""``. A group of two or more windows sends some to the held-out set
    and keeps the rest in the fit, so an effect seen only in a rare manoeuvre can be both
    fitted and confirmed (the excitation plan reverses twice for this)."""
    out = []
    for w, onset in zip(windows, reversal_onsets(log, derived, windows, max_brake_mps2, settings=settings)):
        if onset:
            out.append("brake_to_reverse")
        elif masks["coasting"][w.start:w.stop].any():
            out.append("coast")
        else:
            out.append("")
    return out


def prepare(log: RunLog, car: CarDescription, window_s: float | None = None, pooled: bool = False, *,
            settings: GapSettings = SETTINGS) -> LogPart:
    """One log made ready: checked (``pooled``: as one of several runs), glitches found,
    smoothed, windowed and split."""
    log = check_measured(log, pooled, settings=settings)
    glitches = tuple(find_glitches(log, car, settings=settings))
    bad = glitch_mask(log, glitches)
    derived = derive(log, car.chassis.wheelbase_m, car.steering.limit_rad, exclude=bad, settings=settings)
    unchecked = check_conventions(log, car.chassis.wheelbase_m, car.steering.limit_rad, exclude=bad,
                                  measured=derived, settings=settings)
    windows = make_windows(log, window_s, exclude=bad, settings=settings)
    strata = window_strata(log, derived, segment(log, derived, car, settings=settings), windows,
                           car.drive.max_brake_mps2, settings=settings)
    fit_w, held_w = split_windows(windows, strata=strata, settings=settings) if windows else ([], [])
    return LogPart(log, derived, glitches, tuple(fit_w), tuple(held_w), signals_of(log), unchecked)


def pool_short_runs(parts: list[LogPart], settings: GapSettings = SETTINGS) -> list[LogPart]:
    """Runs too short to split into fit and held-out windows (fewer than
    ``SETTINGS.short_run_windows``), several of them: each is fitted or held out whole, every
    ``holdout_every``-th short run (in the order given) held out, so held-out windows are
    whole runs the fit never saw. Longer runs keep their own split; a single log is as it was."""
    short = [i for i, p in enumerate(parts) if len(p.windows) < settings.short_run_windows]
    if len(parts) < 2 or len(short) < 2:
        return parts
    every = settings.holdout_every
    out = list(parts)
    for k, i in enumerate(short):
        held = k % every == every - 1 or (len(short) < every and k == len(short) - 1)
        windows = parts[i].windows
        out[i] = dataclasses.replace(parts[i], fit_windows=() if held else windows,
                                     held_windows=windows if held else ())
    return out


def choose_hbridge(fit_problem: Problem, held_problem: Problem, delta_bic_min: float) -> dict:
    """A duty car's H-bridge mode (``drive.hbridge``, docs/drive.md): the other mode is taken when
    it lowers the fit windows' BIC by more than ``delta_bic_min`` and the held-out cost too, as
    a chain step must. ``{"chosen", "file", "fit_cost": {mode: cost}, "held_cost": {...}}``."""
    car = fit_problem.car
    modes = ("brake", "coast")
    fit_cost = {m: cost_of(fit_problem, car.replace(drive=dataclasses.replace(car.drive, hbridge=m)))
                for m in modes}
    held_cost = {m: cost_of(held_problem, car.replace(drive=dataclasses.replace(car.drive, hbridge=m)))
                 for m in modes}
    own, other = car.drive.hbridge, next(m for m in modes if m != car.drive.hbridge)
    gain = bic(fit_problem, fit_cost[own], 0) - bic(fit_problem, fit_cost[other], 0)
    chosen = other if gain > delta_bic_min and held_cost[other] < held_cost[own] else own
    return {"chosen": chosen, "file": own, "fit_cost": fit_cost, "held_cost": held_cost}


def run_gap(logs: RunLog | Sequence[RunLog], car: CarDescription | None = None, *, jobs: int = 2,
            effects: Sequence[str] | None = None, settings: GapSettings = SETTINGS,
            sim_factory: SimFactory = default_sim_factory, held_dt_s: float | None = None,
            progress: Callable[[str], None] | None = None, findings: Findings | None = None,
            budget: Budget | None = None, dt_s: float | None = None, window_s: float | None = None,
            delta_bic_min: float | None = None, improvement_min: float | None = None,
            held_improvement_min: float | None = None, max_effects: int | None = None,
            robust_factor: float | None = None, screen_max_s: float | None = None) -> GapResult:
    """Run the workflow of the module docstring on one log or several logs of one car
    (``car`` default: the default car).

    Every log must pass :func:`simrunner.workflows.gap.logs.check_measured` (else
    :class:`simrunner.telemetry.log.LogError`). ``effects`` restricts the candidates (default: the
    whole catalogue); ``progress(label)`` is called as the stages finish. ``findings``
    (:class:`~simrunner.workflows.gap.live.Findings`) records what is found as it is found (each
    log's windows and glitches, the nominal gap, each chain step, the stages and their fits), so
    a run stopped early still has them; ``budget`` (:class:`~simrunner.workflows.gap.live.Budget`)
    ends the chain in time with the model of its finished steps.

    ``settings``: every threshold (:class:`~simrunner.workflows.gap.settings.GapSettings`,
    default the values in force; ``simrunner gap --settings FILE`` overrides some). The
    keywords ``dt_s`` (``workflow_dt_s``), ``window_s``, ``delta_bic_min``, ``improvement_min``,
    ``held_improvement_min``, ``max_effects``, ``robust_factor`` (``robust_window_factor``) and
    ``screen_max_s``, when given, override those fields of ``settings`` for this run.

    ``dt_s`` is the physics step of the fits; ``held_dt_s`` (default: the step of
    ``simrunner drive``, ``RunSettings.dt_s``) that of the held-out confirmation and of the
    before/after figures, so they describe the car file as it will be driven.
    ``robust_factor`` sets the robust window loss (:mod:`simrunner.workflows.gap.fit`;
    ``math.inf``: plain least squares). ``screen_max_s``: the seconds of fit windows the
    chain's screening and refits use on a longer log (a subset by regime,
    :func:`simrunner.workflows.gap.screening.screening_problem`; 0: all of them, slower).
    """
    given = {"workflow_dt_s": dt_s, "window_s": window_s, "delta_bic_min": delta_bic_min,
             "improvement_min": improvement_min, "held_improvement_min": held_improvement_min,
             "max_effects": max_effects, "robust_window_factor": robust_factor, "screen_max_s": screen_max_s}
    settings = dataclasses.replace(settings, **{k: v for k, v in given.items() if v is not None})
    dt_s, window_s, robust_factor = settings.workflow_dt_s, settings.window_s, settings.robust_window_factor
    logs = [logs] if isinstance(logs, RunLog) else list(logs)
    if not logs:
        raise GapError("expected at least one log")
    names = list(CANDIDATES) if effects is None else list(effects)
    unknown = [n for n in names if n not in CANDIDATES]
    if unknown:
        raise GapError(f"unknown effect(s) {', '.join(unknown)} (expected some of {', '.join(CANDIDATES)})")
    car = car or CarDescription()
    duty = [is_duty_log(log) for log in logs]
    if any(duty) and not all(duty):
        raise GapError(f"{', '.join(log.source for log, d in zip(logs, duty) if not d)}: expected duty logs as the "
                       "others (duty_cmd, or duty_left and duty_right): one car, one kind of motor command")
    if all(duty) and car.drive.command != "duty":  # the logs' motors take duties: so does the car
        car = car.replace(drive=dataclasses.replace(car.drive, command="duty", front_share=0.0))
    not_applicable = not_applicable_to(names, car)
    if effects is not None and not_applicable:
        why = "; ".join(f"{n} acts only on a car with {need}" for n, need in not_applicable.items())
        slip = any("tyre_model" in need for need in not_applicable.values())
        raise GapError(f"{why}: expected other effects{' or a car file on slip tyres (--car)' if slip else ''}"
                       f"{' (these logs drive the car by duty)' if all(duty) and not slip else ''}")
    names = [n for n in names if n not in not_applicable]
    tick = progress or (lambda label: None)
    findings = findings if findings is not None else Findings()
    prepared = []
    for log in logs:
        prepared.append(prepare(log, car, window_s, len(logs) > 1, settings=settings))
        findings.add("log", log_text(prepared[-1]), log=log.source, rows=len(log), windows=len(prepared[-1].windows),
                     glitches=len(prepared[-1].glitches), glitch_list=list(prepared[-1].glitches))
    parts = pool_short_runs(prepared, settings)
    signals = tuple(s for s in FIT_SIGNALS if all(s in p.signals for p in parts))
    if not signals:
        raise GapError("the logs have no signal in common to compare (pose or speed)")
    n_fit = sum(len(p.fit_windows) for p in parts)
    n_held = sum(len(p.held_windows) for p in parts)
    if n_fit < 2 or n_held < 1:
        raise GapError(f"{', '.join(p.log.source for p in parts)}: expected at least 3 clean windows of "
                       f"{window_s:g} s (got {n_fit + n_held} after cutting out glitches and gaps)")
    moving = [sum(moves_in(p, p.fit_windows, settings) for p in parts),
              sum(moves_in(p, p.held_windows, settings) for p in parts)]
    if moving[0] < 2 or moving[1] < 1:
        raise GapError(f"{', '.join(p.log.source for p in parts)}: expected the car to move (|speed| >= "
                       f"{settings.moving_mps:g} m/s) in at least 2 fit windows and 1 held-out window (got {moving[0]} "
                       f"of {n_fit} and {moving[1]} of {n_held}): a car at rest shows no effect; drive the plan of "
                       "`simrunner excite`")
    fit_segs = tuple(Segment(p.log, p.derived, p.fit_windows) for p in parts if p.fit_windows)
    held_segs = tuple(Segment(p.log, p.derived, p.held_windows) for p in parts if p.held_windows)

    if held_dt_s is None:
        from simrunner.run.settings import RunSettings

        held_dt_s = RunSettings().dt_s

    def predict(c: CarDescription, step_s: float, which: str = "windows") -> list[Prediction]:
        return [replay(c, p.log, p.derived, getattr(p, which), dt_s=step_s, sim_factory=sim_factory, settings=settings)
                for p in parts]

    fit_pred0 = predict(car, dt_s, "fit_windows")
    fit_res = [residuals(p.log, p.derived, pr) for p, pr in zip(parts, fit_pred0) if p.fit_windows]
    scales = nominal_scales(fit_segs, fit_res, signals, settings)
    fit_problem = Problem(car, fit_segs, scales, signals, dt_s, sim_factory, settings=settings)
    robust = robust_scale_of(window_costs(fit_problem, fit_res), robust_factor)
    fit_problem = dataclasses.replace(fit_problem, robust_scale=robust)
    held_problem = Problem(car, held_segs, scales, signals, held_dt_s, sim_factory, robust, settings)
    findings.add("stage", "replaying the nominal car", stage="replaying the nominal car", fits=1)
    hbridge = None
    if car.drive.command == "duty":  # the H-bridge's mode: a choice of two, made before the chain
        hbridge = choose_hbridge(fit_problem, held_problem, settings.delta_bic_min)
        if hbridge["chosen"] != car.drive.hbridge:
            # the nominal car is now the file's car in the chosen mode: its residuals set the
            # signals' scales and the robust loss, as the file's would have (the wrong mode's
            # residuals, mostly speed, would weigh the signals and flatten the robust loss)
            car = car.replace(drive=dataclasses.replace(car.drive, hbridge=hbridge["chosen"]))
            fit_problem = rescaled(fit_problem.with_car(car), car, robust_factor)
            held_problem = dataclasses.replace(held_problem.with_car(car), scales=fit_problem.scales,
                                               robust_scale=fit_problem.robust_scale)
    started = time.monotonic()
    pred0 = predict(car, held_dt_s)
    closing_s = time.monotonic() - started
    res0_parts = [residuals(p.log, p.derived, pr) for p, pr in zip(parts, pred0)]
    rep_signals = tuple(s for s in REPORT_SIGNALS if all(s in r for r in res0_parts))
    held = np.concatenate([window_mask(len(p.log), p.held_windows) for p in parts])
    findings.base_car = car
    findings.add("nominal", nominal_text(_gap(held_problem, parts, res0_parts),
                                         rmse(_joined(res0_parts, rep_signals), held, rep_signals)),
                 held_gap=_gap(held_problem, parts, res0_parts))
    tick("nominal")
    if budget is not None:  # what the closing stages will cost, measured on this run
        started = time.monotonic()
        cost_of(screening_problem(fit_problem), car)
        budget.measure(time.monotonic() - started, 2.0 * closing_s, jobs)
    chain = build_chain(fit_problem, held_problem, names, jobs=jobs, progress=tick, findings=findings,
                        budget=budget)
    if not chain.stop_reason.startswith("the time budget"):
        findings.add("chain", f"the chain stopped: {chain.stop_reason}", reason=chain.stop_reason)
    findings.add("stage", "the kept parameters' uncertainty", stage="the kept parameters' uncertainty", fits=1)
    car_after = chain.car
    screen = screening_problem(fit_problem)
    # a parameter on a plateau is held (its interval says how well it is pinned, not a curvature)
    curved = [e for e in chain.effects if CANDIDATES[e].field not in chain.spans]
    unc = parameter_uncertainty(screen, car, curved, chain.parameters, jobs=jobs)
    sigma = {**unc.sigma, **{k: math.nan for k in chain.spans}}
    places = screen.window_places()
    one_window = {k: places[w] for k, w in unc.one_window.items()}
    tick("uncertainty")
    findings.add("stage", "the held-out check", stage="the held-out check", fits=1)
    pred1 = pred0 if not chain.effects else predict(car_after, held_dt_s)
    res1_parts = res0_parts if not chain.effects else [residuals(p.log, p.derived, pr)
                                                       for p, pr in zip(parts, pred1)]
    tick("held-out check")
    stat_signals = tuple(dict.fromkeys(rep_signals + tuple(s for s in ("along_m", "cross_m") if s in signals)))
    joined = _joined

    def smoothed(preds):
        return joined([residuals(smoothed_log(p.log, p.derived), p.derived, pr) for p, pr in zip(parts, preds)],
                      rep_signals)

    res0 = joined(res0_parts, tuple(dict.fromkeys(rep_signals + signals + stat_signals)))
    res1 = joined(res1_parts, tuple(dict.fromkeys(rep_signals + signals + stat_signals)))
    seg_masks = [segment(p.log, p.derived, car, settings=settings) for p in parts]
    regime = {k: np.concatenate([m[k] for m in seg_masks]) for k in seg_masks[0]}
    noise = _noise(parts, rep_signals)
    stats_after = residual_stats({s: res1[s] for s in stat_signals}, regime)
    per_log = []
    for p, seg, r0, r1 in zip([p for p in parts if p.held_windows], held_segs,
                              [r for p, r in zip(parts, res0_parts) if p.held_windows],
                              [r for p, r in zip(parts, res1_parts) if p.held_windows]):
        one = dataclasses.replace(held_problem, segments=(seg,))
        mask = window_mask(len(p.log), p.held_windows)
        per_log.append({"log": p.log.source, "held_windows": len(p.held_windows),
                        "gap_before": _gap(one, [p], [r0]), "gap_after": _gap(one, [p], [r1]),
                        "rmse_before": rmse(r0, mask, rep_signals), "rmse_after": rmse(r1, mask, rep_signals)})
    held_ls = dataclasses.replace(held_problem, robust_scale=math.inf)
    in_force = {"robust_scale": fit_problem.robust_scale, "robust_factor": robust_factor, "dt_s": dt_s,
                "held_dt_s": held_dt_s, "window_s": window_s, "jobs": jobs, "delta_bic_min": settings.delta_bic_min,
                "improvement_min": settings.improvement_min, "held_improvement_min": settings.held_improvement_min,
                "max_effects": settings.max_effects, "scales": fit_problem.scales, "signals": list(signals),
                "effects": names,
                "screen_max_s": settings.screen_max_s, "fit_windows_s": sum(g.duration_s for g in fit_problem.segments),
                "screen_windows_s": sum(g.duration_s for g in screen.segments), "hbridge": hbridge}
    result = GapResult(
        effects=chain.effects, parameters=chain.parameters, car=car_after, chain=chain,
        ranking=list(chain.steps[0].screening) if chain.steps else [],
        nominal_cost=chain.nominal_cost, nominal_bic=bic(fit_problem, chain.nominal_cost, 0),
        rmse_before=rmse(res0, held, rep_signals), rmse_after=rmse(res1, held, rep_signals),
        gap_before=_gap(held_problem, parts, res0_parts), gap_after=_gap(held_problem, parts, res1_parts),
        gap_ls_before=_gap(held_ls, parts, res0_parts), gap_ls_after=_gap(held_ls, parts, res1_parts),
        stats_before=residual_stats({s: res0[s] for s in stat_signals}, regime), stats_after=stats_after,
        parts=parts, pred_before=pred0[0], pred_after=pred1[0], settings=in_force,
        rmse_smoothed_before=rmse(smoothed(pred0), held, rep_signals),
        rmse_smoothed_after=rmse(smoothed(pred1), held, rep_signals), noise_rms=noise,
        unrevealable={**missing_manoeuvres(names, parts, car, settings=settings), **cannot_reveal(names, signals)},
        leftovers=leftovers(stats_after, noise, settings=settings), parameter_sigma=sigma,
        parameter_one_window=one_window, per_log=per_log, parameter_spans=dict(chain.spans), gap_settings=settings,
        not_applicable=not_applicable)
    findings.model(result.effects, result.parameters)
    findings.add("done", f"done: effects {result.effect}; held-out gap {result.gap_before:.3g} -> "
                         f"{result.gap_after:.3g}", effects=result.effects, gap_before=result.gap_before,
                 gap_after=result.gap_after)
    return result


def _joined(res_parts: Sequence[dict[str, np.ndarray]], names: Sequence[str]) -> dict[str, np.ndarray]:
    return {s: np.concatenate([r[s] for r in res_parts]) for s in names}


def _glitch_text(g: Glitch) -> str:
    return f"{g.kind.value.replace('_', ' ')} at {g.t_start_s:.2f} s"


def log_text(part: LogPart) -> str:
    """One line on a prepared log: its length, windows and glitches (the first three)."""
    log, gl = part.log, part.glitches
    text = (f"{log.source}: {float(log.t_s[-1] - log.t_s[0]):.1f} s, {len(log)} rows; {len(part.windows)} windows of "
            f"which {len(part.held_windows)} held out; ")
    if not gl:
        return text + "no glitch"
    more = f", and {len(gl) - 3} more" if len(gl) > 3 else ""
    return text + f"{len(gl)} glitch{'es' if len(gl) > 1 else ''} kept out ({'; '.join(map(_glitch_text, gl[:3]))}{more})"


_RMSE_WORDS = {"position_m": ("position", "m"), "yaw_rad": ("heading", "rad"), "speed_mps": ("speed", "m/s"),
               "yaw_rate_radps": ("yaw rate", "rad/s")}


def nominal_text(gap: float, rmse_by_signal: dict[str, float]) -> str:
    """One line on the nominal car: its held-out gap and RMSE per signal."""
    parts = [f"{_RMSE_WORDS.get(s, (s, ''))[0]} {v:.3g} {_RMSE_WORDS.get(s, ('', ''))[1]}".rstrip()
             for s, v in rmse_by_signal.items() if math.isfinite(v)]
    return f"nominal car: held-out gap {gap:.3g}" + (f" (RMSE {', '.join(parts)})" if parts else "")


def moves_in(part: LogPart, windows: Sequence[Window], settings: GapSettings = SETTINGS) -> int:
    """How many of ``windows`` (of ``part``) hold a sample where the car moves (the smoothed
    speed at least ``settings.moving_mps``)."""
    moving = np.abs(np.nan_to_num(part.derived.speed_mps)) >= settings.moving_mps
    return sum(bool(moving[w.start:w.stop].any()) for w in windows)


def _noise(parts: Sequence[LogPart], signals: Sequence[str]) -> dict[str, float]:
    """Sensor noise per report signal over every log (RMS of measured - smoothed, weighted
    by the logs' lengths; NaN where no log measures the signal)."""
    acc: dict[str, list[tuple[float, int]]] = {s: [] for s in signals}
    for p in parts:
        for s, v in noise_rms(p.log, p.derived).items():
            if s in acc and math.isfinite(v):
                acc[s].append((v, len(p.log)))
    return {s: (math.sqrt(sum(v * v * n for v, n in vs) / sum(n for _, n in vs)) if vs else float("nan"))
            for s, vs in acc.items()}


def not_applicable_to(names: Sequence[str], car: CarDescription) -> dict[str, str]:
    """The effects among ``names`` that cannot act on ``car`` (``EffectSpec.applies_to``: the
    slip tyres' effects on a car with rigid tyres): effect -> what the car needs."""
    from simrunner.car.effects import EFFECTS

    return {n: EFFECTS[n].requirement for n in names if not EFFECTS[n].applies_to(car)}


def cannot_reveal(names: Sequence[str], signals: Sequence[str]) -> dict[str, list[str]]:
    """The effects among ``names`` that no available residual signal shows: effect -> the
    signals it would need (``EffectSpec.observed_by``)."""
    from simrunner.car.effects import EFFECTS

    out = {}
    for n in names:
        needs = list(getattr(EFFECTS[n], "observed_by", ()) or ())
        if needs and not any(s in signals for s in needs):
            out[n] = needs
    return out


def missing_manoeuvres(names: Sequence[str], parts: Sequence[LogPart], car: CarDescription, *,
                       settings: GapSettings = SETTINGS) -> dict[str, list[str]]:
    """The effects among ``names`` that act only in a manoeuvre the logs' windows lack in the
    fit or in the held-out set (so no fit can find them, or no held-out window can confirm
    them): effect -> what it would need. Today one: ``esc_brake_reverse`` acts only where a
    reverse command meets a car still rolling forward
    (:func:`simrunner.workflows.gap.regimes.brake_to_reverse`)."""
    if "esc_brake_reverse" not in names:
        return {}
    counts = [0, 0]
    for p in parts:
        for k, windows in enumerate((p.fit_windows, p.held_windows)):
            counts[k] += sum(reversal_onsets(p.log, p.derived, windows, car.drive.max_brake_mps2, settings=settings))
    if min(counts) > 0:
        return {}
    return {"esc_brake_reverse": [f"a reverse command while rolling forward in a fit and in a held-out window "
                                  f"(these logs: {counts[0]} fit, {counts[1]} held out)"]}


# signal -> the noise estimate that bounds it from below (position errors: the pose noise)
_NOISE_OF = {"position_m": "position_m", "along_m": "position_m", "cross_m": "position_m",
             "yaw_rad": "yaw_rad", "speed_mps": "speed_mps", "yaw_rate_radps": "yaw_rate_radps"}


_SIGNAL_WORDS = {"position_m": "position", "along_m": "position along the path",
                 "cross_m": "cross-track position", "yaw_rad": "heading", "speed_mps": "speed",
                 "yaw_rate_radps": "yaw rate"}


def leftovers(stats: Sequence[dict], noise: dict[str, float], ratio: float | None = None,
              min_samples: int | None = None, *, settings: GapSettings = SETTINGS) -> list[dict]:
    """What the final model leaves unexplained, one entry per signal (worst first): the
    regimes where its residual RMSE is at least ``ratio`` times the sensor noise of that
    signal. Signals whose noise the log does not tell (yaw rate without a gyro) are not
    judged. Entry: signal, worst regime, its RMSE, noise and ratio, ``times_all`` (its RMSE
    over the signal's RMSE in all moving samples: how much that regime stands out), every
    regime above the ratio, ``everywhere`` (every judged regime is), and a text such as
    ``unexplained: yaw rate while reversing, 4x noise, 2.5x its level over all windows``."""
    ratio = settings.leftover_noise_ratio if ratio is None else ratio
    min_samples = settings.leftover_min_samples if min_samples is None else min_samples
    per_signal: dict[str, list[dict]] = {}
    judged: dict[str, set[str]] = {}
    level: dict[str, float] = {}
    for row in stats:
        sig, reg = row["signal"], row["regime"]
        floor = noise.get(_NOISE_OF.get(sig, sig), float("nan"))
        if row["count"] < min_samples or not (math.isfinite(floor) and floor > 0):
            continue
        if reg == "all":
            level[sig] = row["rmse"]
        else:
            judged.setdefault(sig, set()).add(reg)
        r = row["rmse"] / floor
        if r >= ratio:
            per_signal.setdefault(sig, []).append({"regime": reg, "rmse": row["rmse"], "times_noise": r,
                                                   "count": row["count"], "noise": floor})
    out = []
    for sig, rows in per_signal.items():
        named = [r for r in rows if r["regime"] != "all"] or rows
        worst = max(named, key=lambda r: r["times_noise"])
        others = sorted({r["regime"] for r in named} - {worst["regime"]})
        everywhere = bool(judged.get(sig)) and {r["regime"] for r in named} >= judged[sig]
        times_all = worst["rmse"] / level[sig] if level.get(sig) else float("nan")
        words = _SIGNAL_WORDS.get(sig, sig)
        text = f"unexplained: {words} while {worst['regime'].replace('_', ' ')}, {worst['times_noise']:.0f}x noise"
        if math.isfinite(times_all) and worst["regime"] != "all":
            text += f", {times_all:.1f}x its level over all windows"
        if everywhere and others:
            text += f" (above {ratio:g}x noise in every regime: the model misses {words} throughout)"
        elif others:
            text += f" (also above {ratio:g}x noise: {', '.join(o.replace('_', ' ') for o in others)})"
        out.append({"signal": sig, "regime": worst["regime"], "rmse": worst["rmse"], "noise": worst["noise"],
                    "times_noise": worst["times_noise"], "times_all": times_all, "everywhere": everywhere,
                    "regimes": [r["regime"] for r in named], "text": text})
    return sorted(out, key=lambda d: -d["times_noise"])


def _gap(held_problem: Problem, parts: Sequence[LogPart], res_parts: Sequence[dict[str, np.ndarray]]) -> float:
    """The held-out gap: ``cost / n_values`` of ``held_problem`` (its robust window loss, or
    least squares when its ``robust_scale`` is inf) for the residuals ``res_parts`` (one per
    log of ``parts``; logs without held-out windows are skipped, as in the problem)."""
    res = [r for p, r in zip(parts, res_parts) if p.held_windows]
    return robust_total(window_costs(held_problem, res), held_problem.robust_scale) / max(held_problem.n_values, 1)
