"""Several effects at once: the model is built step by step (forward selection).

Step ``s`` starts from the car with the effects kept so far (their parameters as last
refitted) and

1. screens every remaining catalogue effect: a one-parameter fit of the new effect with
   the kept parameters held (:func:`simrunner.workflows.gap.fit.fit_all`, grid + probes), on
   about ``settings.screen_max_s`` seconds of the fit windows (``build_chain``'s ``screen_max_s``,
   ``--screen``; 0: all of them), spread evenly over the log's time
   grid with the first window of each driving regime (:func:`screening_problem`: screening only
   ranks, so a long log costs no more than
   a 45-s one here, and a rare manoeuvre is not left out; nor are the windows that steer
   hardest, :func:`extreme_windows`);
2. refits jointly the ``settings.refine_top`` best screened candidates (``settings.refine_later``
   from the second step on): all kept parameters and the new one together
   (``scipy.optimize.minimize``, Powell, in coordinates scaled to each parameter's fit
   bounds, the new parameter's coordinate searched first (:func:`joint_refit`); bounded
   Brent for the first step, which has one parameter), on the screening
   windows; the result is then scored once on all fit windows and once on the held-out ones.
   From the second step on, the kept effects alone are refitted the same way (the
   *baseline*): a candidate must beat the current model at its best, not only the
   parameters the last step left, so a candidate cannot pass on the kept parameters'
   refit alone. After a step that kept a candidate, the baseline is that candidate's second
   refit (below), done already;
3. tries them in order of the information criterion (BIC with ``k`` = the number of fitted
   parameters); the first that passes the four tests below is refitted once more from its
   values [shaped by the shared logs] (the budget of one refit can end before the kept parameters have moved: DS3's
   pose-only brake scale was judged at a point its next refit bettered by 17 % on the
   held-out windows), and kept if it passes them again with those figures and its held-out
   gap on the report's normalisation has not grown (the tests judge on the step's
   normalisation, step 6; a gain that only that weighting of the signals shows is not one
   the report can show). The four tests, against the current model:
   its own parameter left its neutral value (by more than ``settings.neutral_tol`` of its fit
   range), ``delta_bic >= settings.delta_bic_min`` and ``improvement >= settings.improvement_min`` on the fit
   windows (the thresholds calibrated on effect-free logs) **and** a held-out gap at least
   ``settings.held_improvement_min`` smaller than before on the held-out windows, which no fit has
   seen (the held-out problem may use a finer physics step than the fits: the step
   ``simrunner drive`` uses, so what is kept holds for the car file as it will be driven);
4. when every refitted candidate fails, refits the next ones in the screening order, in
   batches of the same size, every one whose screening fit gained at least
   ``settings.improvement_min / settings.safety`` (half of it: the largest gain an effect-free log's best
   candidate showed; a one-parameter gain below that is not worth a refit). The gate is
   a test and judges where the tests do: on all fit windows and on the step's
   normalisation (step 6), each candidate replayed once at its screened value (the
   screening's own figures when they are those: the first step of a log the subset holds
   whole). Multi log 0's drag, screened beside a deadband on a subset that left out the
   windows at the plan's top speed, gained 0.4 % there on the nominal scales, 8.4 % on all
   fit windows on the step's. There is no
   count limit: with a few kept effects held, a candidate that only helps once a kept one
   is refitted with it can screen behind several that fail [shaped by the shared logs] (DS2's third effect screened
   7th, behind six that the tests rejected; a limit of 6 refits a step cut it off);
5. once an effect is kept at a step past the first, tries exchanges: each effect kept at an
   earlier step is replaced in turn by each of the ``settings.refine_top`` best candidates
   refitted at that step and not kept (its runners-up), all kept parameters refitted
   jointly with the replacement; the best exchange that lowers the fit windows' cost (same
   number of parameters: a lower BIC) and does not worsen the held-out gap is made, and
   the exchanges repeat until none helps (``settings.max_exchanges`` at most). A look-alike that
   won a near tie early (a mass scale
   for a brake scale, an asymmetry for an offset) is swapped for the effect the later ones
   fit with; ``Chain.swaps`` records each with its figures;
6. sets the normalisation the next step judges on (:func:`renormalised`): every signal's
   scale becomes the RMS of the current model's residuals on the fit windows (the robust
   window scale likewise), so the tests of step 3 weigh every signal the same again, as
   they do at the first step under the nominal model, where the thresholds were calibrated
   (effect-free logs: every signal's normalised cost about 1). Under the nominal scales a
   strong first effect leaves its signals far below 1 while an untouched signal stays at
   its noise, and a second effect on the same signals is judged against a cost it barely
   touches (a steering asymmetry next to a strong offset: 1.6 % of the fit cost; 36 % of
   it on the renormalised signals; bench/results/gap-history.md). The fits themselves keep minimising the
   cost on the problems' normalisation, the report's, so the parameters and the held-out
   gaps reported are those of one objective; only the tests' figures (``Trial.delta_bic``,
   ``improvement``, ``held_gap``, ``Step.held_gap_before``) are on the step's;
7. stops when no candidate passes, or with ``settings.max_effects`` effects kept;
8. then checks every kept effect once more (backward elimination): with two or more kept,
   each is left out in turn and the others refitted; an effect that would no longer pass
   the tests of step 3 as the last one added (against the others refitted without it) at
   the thresholds to *stay* is removed (so is one whose removal would not make the
   report's held-out gap grow), the weakest first, and the check repeats. To enter, a
   candidate needs ``settings.safety`` times the largest
   ``delta_bic``, fit improvement and held-out gain an effect-free log's best candidate
   showed (the calibration, ``thresholds.py``); to stay, an effect the held-out windows
   confirmed on entry needs that largest value itself (:func:`staying`): a gain beside
   the others that no effect-free log reaches is not noise. This is the hysteresis of
   stepwise regression (Efroymson 1960: an F-to-remove below the F-to-enter), without
   which an effect that a later one takes a little from is removed at a gain that admits
   no false claim [shaped by the shared logs] (DS2's brake scale: 6.6 % beside two later effects, against 6.8 % to
   enter and 3.4 % at most on an effect-free log; removing it grows the held-out gap
   20 %). A look-alike kept early (a slower servo standing in for a latency found later)
   gains about nothing beside the real effect and goes; ``Chain.pruned`` records it with
   its reason (``Chain.pruned_after``: the last step before that check);
9. when the check removed an effect, resumes the forward steps from the smaller model (on
   its normalisation; a removed effect is not tried again), then checks again after any
   step that kept something: stepwise selection in both directions. A look-alike that took
   a place of a chain at its limit no longer shuts out the effect the data hold next, and
   a candidate the look-alike made fail is tried again without it.

A candidate that passed a step's tests but lost to the kept one is compared with it window
by window (fit and held-out windows, the step's normalisation): when the two models' costs
differ by less than ``settings.alike_z`` standard errors (Vuong's test), the windows cannot tell
them apart and ``Step.alike`` records it, for the report to say so. This changes nothing in
the chain: it names the kept one, and a near tie's name is the report's to qualify.

"[shaped by the shared logs]" marks a rule the two shared real logs (DS2, DS3,
``../shared/data/real_logs``) gave its form; the settings flag such values (``shared_logs``).

Every candidate that was tried and not kept is recorded with its reason. The chain's
result is the car with all kept effects; its parameters are those of the last joint refit.

In the code, :func:`build_chain` runs a :class:`_ChainBuilder`, whose methods are the steps
above: :meth:`~_ChainBuilder.forward_step` (``baseline``: step 2's baseline, ``screen``: 1,
``decide`` with ``refit``, ``polish`` and ``gate``: 2-4, ``exchange``: 5, ``rejudge``: 6, its
``False``: 7), :meth:`~_ChainBuilder.backward_check` (8) and :meth:`~_ChainBuilder.build`, which
alternates them (9). Each joint refit is a :class:`RefitJob` a worker process runs. The
thresholds are :mod:`simrunner.workflows.gap.settings`'s.
"""
from __future__ import annotations

import dataclasses
import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from simrunner.workflows.gap.fit import (CANDIDATES, FitResult, Problem, _quiet_worker,
                                         bic, cost_of, fit_all, rescaled, robust_total, segment_residuals,
                                         window_costs, window_values_task)
from simrunner.workflows.gap.live import Budget, BudgetSpent, Findings
from simrunner.workflows.gap.screening import screening_problem
from simrunner.workflows.gap.settings import SETTINGS, GapSettings
from vehicle.description import CarDescription

# The thresholds (units, derivations, sources: simrunner.workflows.gap.settings)
BETTER = "a better candidate was kept"


def with_parameters(car: CarDescription, parameters: dict[str, float]) -> CarDescription:
    """``car`` with the ``Effects`` fields of ``parameters`` set."""
    if not parameters:
        return car
    return car.replace(effects=dataclasses.replace(car.effects, **{k: float(v) for k, v in parameters.items()}))


@dataclass(frozen=True)
class Trial:
    """One candidate at one step after its joint refit."""

    effect: str
    parameters: dict[str, float]  # every fitted parameter (kept ones and the new one)
    cost: float         # fit windows, on the problems' normalisation (what the refit minimised)
    # the tests' figures, on the step's normalisation (module docstring, step 6):
    delta_bic: float    # against the current model
    improvement: float  # 1 - cost / current cost, fit windows
    held_gap: float     # held-out gap with these parameters
    evaluations: int
    kept: bool = False
    reason: str = ""
    spans: dict[str, tuple[float, float]] = dataclasses.field(default_factory=dict)  # joint_refit's

    def to_json(self) -> dict:
        return {"effect": self.effect, "parameters": self.parameters, "cost": self.cost,
                "delta_bic": self.delta_bic, "improvement": self.improvement,
                "held_gap": self.held_gap, "evaluations": self.evaluations, "kept": self.kept,
                "reason": self.reason, "spans": self.spans}


@dataclass(frozen=True)
class Alike:
    """A candidate that passed a step's tests where another was kept, and that the windows
    cannot tell from the kept one: the mean over the fit and held-out windows of its cost
    minus the kept one's (each window's robust cost, on the step's normalisation) is within
    ``settings.alike_z`` standard errors of 0 (``z``; > 0: the kept one fits better)."""

    effect: str
    parameters: dict[str, float]  # every fitted parameter of the model with it
    z: float
    windows: int

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


def vuong_z(kept: np.ndarray, other: np.ndarray) -> float:
    """Per-window costs ``other - kept``: their mean over its standard error (Vuong's
    statistic; 0 for identical costs, +-inf for a difference without spread)."""
    d = np.asarray(other, float) - np.asarray(kept, float)
    mean = float(d.mean()) if d.size else 0.0
    sd = float(d.std(ddof=1)) if d.size > 1 else 0.0
    if sd == 0.0:
        return 0.0 if mean == 0.0 else math.copysign(math.inf, mean)
    return mean / (sd / math.sqrt(d.size))


@dataclass(frozen=True)
class Step:
    """One step of the chain: the screening ranking, the refitted trials, what was kept."""

    index: int
    held_gap_before: float  # the current model's, on this step's normalisation (``scales``), as the trials'
    screening: tuple[FitResult, ...]
    trials: tuple[Trial, ...]
    scales: dict[str, float] = dataclasses.field(default_factory=dict)  # the step's normalisation
    gap_before: float = math.nan  # held-out gap of the model before / after the step on the
    gap_after: float = math.nan   # problems' normalisation (the report's: GapResult.gap_before/after)
    alike: tuple[Alike, ...] = ()  # candidates the windows cannot tell from the kept one

    @property
    def kept(self) -> Trial | None:
        return next((t for t in self.trials if t.kept), None)

    def to_json(self) -> dict:
        kept = self.kept
        return {"step": self.index, "kept": kept.effect if kept else None,
                "parameters": kept.parameters if kept else {},
                "held_gap_before": self.gap_before, "held_gap_after": self.gap_after,
                "scales": self.scales, "step_held_gap_before": self.held_gap_before,
                "trials": [t.to_json() for t in self.trials],
                "alike": [a.to_json() for a in self.alike],
                "screened": [r.to_json() for r in self.screening]}


@dataclass(frozen=True)
class Swap:
    """An exchange after step ``step``: ``out`` (kept at an earlier step) replaced by
    ``into`` (one of that step's runners-up), every kept parameter refitted."""

    step: int
    out: str
    into: str
    parameters: dict[str, float]  # every kept parameter after the exchange
    cost_before: float
    cost_after: float      # fit windows
    held_gap_before: float
    held_gap_after: float
    spans: dict[str, tuple[float, float]] = dataclasses.field(default_factory=dict)  # joint_refit's

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Chain:
    """The steps taken; ``car`` has every kept effect."""

    steps: tuple[Step, ...]
    car: CarDescription
    nominal_cost: float      # fit windows, nominal car
    nominal_held_gap: float  # held-out windows, nominal car
    stop_reason: str = ""
    parameters: dict[str, float] = dataclasses.field(default_factory=dict)  # the final refit of every kept parameter
    pruned: tuple[Trial, ...] = ()  # kept by a step, removed by the final check (the trial: the model with it)
    swaps: tuple[Swap, ...] = ()  # exchanges, in the order made
    pruned_after: tuple[int, ...] = ()  # per pruned trial: the last step before the check that removed it
    # kept parameters the fit windows pin only to an interval (a plateau, kept at its middle): (low, high)
    spans: dict[str, tuple[float, float]] = dataclasses.field(default_factory=dict)

    @property
    def effects(self) -> list[str]:
        """The kept effects in the order their slots were filled (an exchanged effect in
        its predecessor's place), without those the final check removed."""
        names = [s.kept.effect for s in self.steps if s.kept is not None]
        for sw in self.swaps:
            names[names.index(sw.out)] = sw.into
        gone = {t.effect for t in self.pruned}
        return [n for n in names if n not in gone]

    @property
    def rejected(self) -> list[tuple[int, Trial]]:
        """``(step, trial)`` of the refitted candidates that failed a test (not those only
        passed over for a better one at a step that kept something)."""
        return [(s.index, t) for s in self.steps for t in s.trials if not t.kept and t.reason != BETTER]

    def to_json(self) -> list[dict]:
        return [s.to_json() for s in self.steps]


def _bounds01(names: Sequence[str]):
    cands = [CANDIDATES[n] for n in names]

    def to_u(values: dict[str, float]) -> np.ndarray:
        return np.array([c.u(values[c.field]) for c in cands])

    def from_u(u: np.ndarray) -> dict[str, float]:
        out = {}
        for c, ui in zip(cands, np.clip(u, 0.0, 1.0)):
            lo, hi = c.to_x(c.lo), c.to_x(c.hi)
            out[c.field] = float(min(max(c.from_x(lo + ui * (hi - lo)), c.lo), c.hi))
        return out

    return to_u, from_u


def joint_refit(problem: Problem, base: CarDescription, names: Sequence[str],
                start: dict[str, float], first: str | None = None, *, settings: GapSettings = SETTINGS
                ) -> tuple[dict[str, float], float, int, dict[str, tuple[float, float]]]:
    """Refit the parameters of effects ``names`` together from ``start`` (their ``Effects``
    fields), on ``problem``'s windows with ``base`` as the car: ``(values, cost, evals,
    spans)``, ``values`` in the order of ``names``; ``spans`` maps each parameter the cost
    pins only to an interval (:func:`_plateaus`: moved to its middle) to ``(low, high)``.
    One parameter: bounded Brent around the start; more: Powell in [0, 1]-scaled coordinates,
    whose first pass line-searches one coordinate after the other, ``first`` (an effect of
    ``names``: the one just added) before the others. Each line search spans the whole fit
    range (about a dozen evaluations), so the budget of ``settings.powell_evals_per_parameter`` per
    parameter can end inside the first pass: searched last, a new effect's parameter
    would keep its screening value (multi log 25's steering gain, bench/results/gap-history.md), while the
    kept ones start at their last refit and move little. ``settings``: the thresholds (the
    problem's, as :func:`_trial_task` passes them)."""
    given = list(names)
    if first is not None:
        names = [first] + [n for n in given if n != first]
    to_u, from_u = _bounds01(names)
    seen: dict[tuple, float] = {}

    def f(u) -> float:
        values = from_u(np.atleast_1d(np.asarray(u, dtype=float)))
        key = tuple(values[CANDIDATES[n].field] for n in names)
        if key not in seen:
            seen[key] = cost_of(problem, with_parameters(base, values))
        return seen[key]

    u0 = to_u(start)
    f(u0)
    if len(names) == 1:
        a, b = max(u0[0] - 0.25, 0.0), min(u0[0] + 0.25, 1.0)
        minimize_scalar(lambda x: f([x]), bounds=(a, b), method="bounded",
                        options={"xatol": 2e-3, "maxiter": settings.brent_maxiter})
    else:
        minimize(f, u0, method="Powell", bounds=[(0.0, 1.0)] * len(names),
                 options={"xtol": 2e-3, "ftol": 1e-4,
                          "maxfev": settings.powell_evals_per_parameter * len(names)})
    key = min(seen, key=lambda k: (seen[k], k))
    tie = seen[key] * math.exp(settings.tie_delta_bic / problem.n_eff) if problem is not None else seen[key]
    key, spans = _plateaus(f, names, to_u, dict(zip((CANDIDATES[n].field for n in names), key)), tie, settings)
    values = dict(zip((CANDIDATES[n].field for n in names), key))
    return {CANDIDATES[n].field: values[CANDIDATES[n].field] for n in given}, seen[key], len(seen), spans


def _plateaus(f, names: Sequence[str], to_u, values: dict[str, float],
              tie: float, settings: GapSettings) -> tuple[tuple, dict[str, tuple[float, float]]]:
    """The fitted ``values`` (``Effects`` fields of ``names``) with every parameter that sits on
    a plateau of the cost ``f`` (of ``[0, 1]``-scaled coordinates) moved to its middle: ``(the
    key of the point reached, {field: (plateau's low end, high end)})``.

    A parameter the fit windows pin only to an interval (a deadband between zero and the
    smallest speed command they hold, a top speed above the fastest they reach) leaves the
    search at whatever point of the plateau it stopped on, possibly one end, and any value
    in the interval is as likely to be the car's (multi log 10: a deadband of 0.033 m/s
    fitted at 0.5 m/s, where the fit windows cost the same from 0.001 to 0.3 m/s, and
    held-out windows with 0.3-0.4 m/s commands contradicted it; log 0: 0.27 m/s, the same
    plateau, the search at 0.095). The middle is nearest to every value of the interval at
    worst, and the report gives the interval instead of a standard error.

    One probe halfway to neutral decides: a cost that rises towards neutral by more than
    ``tie`` (every pinned parameter) leaves the value as it is. On a plateau, each end is
    found by bisection (``settings.tie_bisections`` steps; the end towards neutral never nearer
    than twice ``settings.neutral_tol`` of the fit range, which counts as no effect), and the
    middle is kept if it is on the plateau too (else the value found). A search that stopped
    within that band of neutral, on a plateau that reaches beyond it, while neutral itself
    costs more than ``tie`` (a cliff at neutral: any deadband above a few mm/s fits as well,
    none fits far worse), is moved out along the plateau the same way; at or as good as
    neutral, or pinned inside the band, it stays (and the chain rejects it as no effect)."""
    u = to_u(values)
    moved = False
    spans: dict[str, tuple[float, float]] = {}
    for i, name in enumerate(names):
        c = CANDIDATES[name]
        n_u = _neutral_u(name)
        side = math.copysign(1.0, u[i] - n_u)
        near_limit = n_u + side * 2.0 * settings.neutral_tol
        within = (u[i] - near_limit) * side <= 0.0

        def at(x: float) -> np.ndarray:
            p = u.copy()
            p[i] = x
            return p

        if within and (u[i] == n_u or f(at(n_u)) <= tie or f(at(near_limit)) > tie):
            continue  # neutral, as good as neutral, or pinned near it

        def edge(inside: float, outside: float) -> float:
            if f(at(outside)) <= tie:
                return outside
            for _ in range(settings.tie_bisections):
                mid = 0.5 * (inside + outside)
                if f(at(mid)) <= tie:
                    inside = mid
                else:
                    outside = mid
            return inside

        if within:
            # a plateau from a cliff at neutral outwards, the search stopped at its near end
            # (multi log 10: a deadband costs the same from 0.004 to 0.04 m/s, 2x more at 0)
            near, start = edge(u[i], n_u), near_limit
        else:
            half = 0.5 * (u[i] + near_limit)
            if f(at(half)) > tie:
                continue  # the cost rises towards neutral: pinned
            near, start = edge(half, near_limit), u[i]
        far = edge(start, 1.0 if side > 0 else 0.0)
        middle = 0.5 * (near + far)
        x = middle if f(at(middle)) <= tie else u[i]
        _, one_from_u = _bounds01([name])
        ends = sorted((one_from_u(np.array([near]))[c.field], one_from_u(np.array([far]))[c.field]))
        spans[c.field] = (ends[0], ends[1])
        if x != u[i]:
            u, moved = at(x), True
    if not moved:
        return tuple(values[CANDIDATES[n].field] for n in names), spans
    _, from_u = _bounds01(names)
    reached = from_u(u)
    return tuple(reached[CANDIDATES[n].field] for n in names), spans


@dataclass(frozen=True)
class Judge:
    """The normalisation a step judges its candidates on (step 6 of the module docstring):
    the fit and held-out problems with the scales of the current model's residuals."""

    fit: Problem
    held: Problem


@dataclass(frozen=True)
class Outcome:
    """A refit's result: the values, the fit-window cost and held-out gap on the problems'
    (the report's) normalisation, and the same two on the step's (``judged_*``)."""

    values: dict[str, float]
    cost: float
    evaluations: int
    held_gap: float
    judged_cost: float
    judged_held_gap: float
    spans: dict[str, tuple[float, float]] = dataclasses.field(default_factory=dict)  # joint_refit's


def judged(problem: Problem, judge: Problem, car: CarDescription) -> tuple[float, float]:
    """``car``'s cost on ``problem`` and on ``judge`` (same windows, other scales): one replay."""
    res = segment_residuals(problem, car)
    cost = robust_total(window_costs(problem, res), problem.robust_scale)
    if judge is problem:
        return cost, cost
    return cost, robust_total(window_costs(judge, res), judge.robust_scale)


def _cost_task(args) -> float:
    problem, car = args
    return cost_of(problem, car)


@dataclass(frozen=True)
class RefitJob:
    """One joint refit for a worker (:func:`_trial_task`): the parameters of the effects
    ``names`` refitted together from ``start`` on ``screen``'s windows (``first``'s searched
    first; :func:`joint_refit`) with ``base`` as the car, then scored on all ``fit`` windows and
    on the ``held``-out ones, on the problems' normalisation and on ``judge``'s."""

    screen: Problem
    fit: Problem
    held: Problem
    judge: Judge
    base: CarDescription
    names: tuple[str, ...]
    start: dict[str, float]
    first: str | None = None


def _trial_task(job: RefitJob) -> Outcome:
    values, _, evals, spans = joint_refit(job.screen, job.base, job.names, job.start, job.first,
                                         settings=job.screen.settings)
    car = with_parameters(job.base, values)
    cost, j_cost = judged(job.fit, job.judge.fit, car)
    held, j_held = judged(job.held, job.judge.held, car)
    n = max(job.held.n_values, 1)
    return Outcome(values, cost, evals, held / n, j_cost, j_held / n, spans)


def neutral_offset(name: str, value: float) -> float:
    """How far ``value`` of effect ``name`` lies from its neutral value, as a fraction of its
    fit range in the fit's coordinates (log scale where the fit searches in log scale; a
    neutral value outside the fit bounds is taken at the nearest bound)."""
    to_u, _ = _bounds01([name])
    return float(abs(to_u({CANDIDATES[name].field: value})[0] - _neutral_u(name)))


def _neutral_u(name: str) -> float:
    """Effect ``name``'s neutral value in the fit's ``[0, 1]`` coordinates (a neutral value
    outside the fit bounds taken at the nearest bound)."""
    from simrunner.car.effects import EFFECTS

    to_u, _ = _bounds01([name])
    c = CANDIDATES[name]
    return float(to_u({c.field: min(max(EFFECTS[name].neutral[0], c.lo), c.hi)})[0])


def build_chain(fit_problem: Problem, held_problem: Problem, names: Sequence[str], *, jobs: int = 2,
                progress: Callable[[str], None] | None = None, findings: Findings | None = None,
                budget: Budget | None = None) -> Chain:
    """Run the stepwise selection of the module docstring over the effects ``names``.

    ``fit_problem`` and ``held_problem`` have the same base car (no chain effect yet), the
    same signals and scales; the held-out gap is ``cost / n_values`` of ``held_problem``
    (whose physics step may be finer than the fit problem's). Every fit minimises the cost
    on their normalisation; the tests of step 3 judge on the step's. The thresholds are the
    fit problem's ``settings`` (:class:`~simrunner.workflows.gap.settings.GapSettings`): ``delta_bic_min``,
    ``improvement_min``, ``held_improvement_min``, ``max_effects``, ``robust_window_factor``
    (the robust window scale's factor, as ``run_gap``'s), ``screen_max_s`` (the seconds of fit
    windows the screening and the refits use, :func:`screening_problem`; 0: all of them), ...

    ``findings`` (:class:`~simrunner.workflows.gap.live.Findings`) records each stage, step,
    exchange and removal as it is made; ``budget`` (:class:`~simrunner.workflows.gap.live.Budget`)
    ends the chain with the model of the finished steps when the time left is what the closing
    stages need (``Chain.stop_reason`` says so)."""
    return _ChainBuilder(fit_problem, held_problem, names, jobs=jobs, progress=progress, findings=findings,
                         budget=budget).build()


@dataclass
class _StepState:
    """What one forward step works with: its index, the number of effects kept before it, the
    screening subset of the nominal-car problem (the refits' windows), the current model's
    full and screening problems, the screening ranking and the refits' outcomes so far."""

    index: int
    k: int
    screen_base: Problem
    full: Problem
    screen: Problem
    screening: list[FitResult]
    ranked: list[FitResult]
    n_top: int
    crit_now: float
    outcome: dict[str, Outcome] = dataclasses.field(default_factory=dict)


class _ChainBuilder:
    """The chain's state while it is built (module docstring): the kept effects, their
    parameters and spans, the current model's costs (on the problems' normalisation and on the
    step's, ``judge``), the steps, exchanges and removals so far. :meth:`build` runs the named
    steps: :meth:`forward_step` (:meth:`baseline`, :meth:`screen`, :meth:`refit` in batches,
    :meth:`gate`, :meth:`polish`, :meth:`exchange`), :meth:`backward_check`, and again."""

    def __init__(self, fit_problem: Problem, held_problem: Problem, names: Sequence[str], *, jobs: int,
                 progress: Callable[[str], None] | None, findings: Findings | None = None,
                 budget: Budget | None = None):
        self.fit_problem, self.held_problem, self.names = fit_problem, held_problem, list(names)
        self.settings = s = fit_problem.settings
        self.jobs, self.tests, self.max_effects = jobs, (s.delta_bic_min, s.improvement_min,
                                                         s.held_improvement_min), s.max_effects
        self.robust_factor, self.screen_max_s = s.robust_window_factor, s.screen_max_s
        self.progress = progress or (lambda label: None)
        self.findings = findings or Findings()
        self.budget = budget
        self.base = fit_problem.car
        self.order = {n: i for i, n in enumerate(CANDIDATES)}
        self.kept_names: list[str] = []
        self.kept_values: dict[str, float] = {}
        self.kept_spans: dict[str, tuple[float, float]] = {}  # of the refit that set kept_values
        self.cost = cost_of(fit_problem, self.base)
        self.held_gap = cost_of(held_problem, self.base) / max(held_problem.n_values, 1)
        self.nominal_cost, self.nominal_held = self.cost, self.held_gap
        self.judge = Judge(fit_problem, held_problem)  # step 1: the nominal model's normalisation
        self.j_cost, self.j_held = self.cost, self.held_gap  # the current model as the step judges it
        self.steps: list[Step] = []
        self.swaps: list[Swap] = []
        self.runners_up: dict[str, list[Trial]] = {}  # per kept effect: its step's other refitted candidates
        self.stop = ""
        self.index = 0
        self.excluded: set[str] = set()  # removed by a check: not tried again
        self.pruned: list[Trial] = []
        self.pruned_after: list[int] = []  # the last step before each removal
        self.polished = False  # the kept parameters come from a kept candidate's second refit
        self.pool: ProcessPoolExecutor | None = None

    # -- progress, findings, budget ---------------------------------------------------------------
    def tick(self, label: str) -> None:
        """A fit (or a batch of fits) done; raises BudgetSpent when the budget keeps the rest
        of the time for the closing stages."""
        self.progress(label)
        if self.budget is not None:
            self.budget.tick()
            if self.budget.spent(len(self.kept_names) + 1):
                raise BudgetSpent(label)

    def stage(self, text: str, fits: int) -> None:
        self.findings.add("stage", text, stage=text, fits=int(fits))

    def model_changed(self) -> None:
        self.findings.model(self.kept_names, self.kept_values)

    # -- workers -------------------------------------------------------------------------------
    def job(self, screen: Problem, names: Sequence[str], start: dict[str, float],
            first: str | None = None) -> RefitJob:
        return RefitJob(screen, self.fit_problem, self.held_problem, self.judge, self.base, tuple(names),
                        dict(start), first)

    def run(self, jobs: list[RefitJob]) -> list[Outcome]:
        return list(self.pool.map(_trial_task, jobs)) if self.pool is not None else [_trial_task(j) for j in jobs]

    def costs(self, tasks) -> list[float]:
        return list(self.pool.map(_cost_task, tasks)) if self.pool is not None else [_cost_task(t) for t in tasks]

    def values_per_window(self, tasks) -> list[np.ndarray]:
        return (list(self.pool.map(window_values_task, tasks)) if self.pool is not None
                else [window_values_task(t) for t in tasks])

    def rejudge(self) -> None:
        """Step 6: the normalisation of the current model, its fit cost and held-out gap on it."""
        current = with_parameters(self.base, self.kept_values)
        self.judge, self.j_cost = renormalised(self.fit_problem, self.held_problem, current, self.robust_factor)
        self.j_held = cost_of(self.judge.held, current) / max(self.held_problem.n_values, 1)

    # -- the whole selection -------------------------------------------------------------------
    def build(self) -> Chain:
        self.pool = ProcessPoolExecutor(max_workers=self.jobs, initializer=_quiet_worker) if self.jobs > 1 else None
        try:
            checked = 0  # steps that kept an effect, at the last check
            while True:  # forward steps, then the check; again while the check removes something
                while self.forward_step():
                    pass
                n_kept = sum(st.kept is not None for st in self.steps)
                if self.pruned and n_kept == checked:  # resumed, and nothing kept since the last check
                    break
                checked, n_pruned = n_kept, len(self.pruned)
                self.backward_check()
                if len(self.pruned) == n_pruned:
                    break
                # stepwise: the forward steps resume on the smaller model (step 9 of the module docstring)
                self.excluded.update(t.effect for t in self.pruned[n_pruned:])
                self.runners_up = {e: [t for t in ts if t.effect not in self.excluded]
                                   for e, ts in self.runners_up.items()}
                self.rejudge()
        except BudgetSpent:
            self.stop = (f"the time budget ({self.budget.minutes()}) ran out during {self.findings.stage}: "
                         "the model of the finished steps" + (", not re-checked by the final check"
                                                              if len(self.kept_names) > 1 else ""))
            self.findings.add("chain", f"stopped: {self.stop}", reason=self.stop)
        finally:
            if self.pool is not None:
                self.pool.shutdown(cancel_futures=True)
        return Chain(tuple(self.steps), with_parameters(self.base, self.kept_values), self.nominal_cost,
                     self.nominal_held, self.stop, dict(self.kept_values), tuple(self.pruned), tuple(self.swaps),
                     tuple(self.pruned_after),
                     {k: v for k, v in self.kept_spans.items() if k in self.kept_values})

    # -- a forward step (steps 1-7 of the module docstring) -------------------------------------
    def forward_step(self) -> bool:
        """One forward step; False when the forward steps stop (``self.stop`` says why)."""
        if len(self.kept_names) >= self.max_effects:
            self.stop = (f"the chain reached its limit of {self.max_effects} effects (more may pass: "
                         "`--max-effects N`, `max_effects=N`)") if self.max_effects else "max effects 0: nothing tried"
            return False
        remaining = [n for n in self.names if n not in self.kept_names and n not in self.excluded]
        if not remaining:
            self.stop = "every candidate effect is in the model"
            return False
        if self.budget is not None and self.budget.spent(len(self.kept_names) + 1):
            raise BudgetSpent("before a step")
        self.index += 1
        screen_base = screening_problem(self.fit_problem, self.screen_max_s)
        if self.kept_names and not self.polished:
            self.baseline(screen_base)
        st = self.screen(screen_base, remaining)
        chosen, decided = self.decide(st)
        alike = () if chosen is None else self.alike_of(chosen, [t for t in decided if t.reason == BETTER],
                                                         st.outcome)
        self.steps.append(Step(st.index, self.j_held,
                               tuple(sorted(st.screening, key=lambda r: (r.criterion, self.order[r.effect]))),
                               tuple(decided), dict(self.judge.fit.scales), self.held_gap,
                               self.held_gap if chosen is None else st.outcome[chosen.effect].held_gap, alike))
        step = self.steps[-1]
        if chosen is None:
            self.stop = "no remaining effect passes the tests"
            self.findings.add("step", f"step {st.index}: no remaining effect passes the tests", step=st.index,
                              kept=None)
            return False
        self.keep(chosen, st, decided)
        self.model_changed()
        self.findings.add("step", f"step {st.index}: kept {chosen.effect} ({_values_text(chosen.parameters, chosen.effect)}); "
                                  f"held-out gap {step.gap_before:.3g} -> {step.gap_after:.3g}",
                          step=st.index, kept=chosen.effect, parameters=dict(self.kept_values),
                          held_gap_before=step.gap_before, held_gap_after=step.gap_after)
        for _ in range(self.max_exchanges_now()):
            self.stage(f"step {st.index}: exchanges", 1)
            more = self.exchange(st)
            self.tick(f"step {st.index} exchanges")
            if not more:
                break
        self.rejudge()  # module docstring, step 6
        return True

    def baseline(self, screen_base: Problem) -> None:
        """Step 2's baseline: the kept effects alone, refitted as the candidates will be."""
        self.stage(f"step {self.index}: refit of the kept effects", 1)
        b, = self.run([self.job(screen_base, self.kept_names, self.kept_values)])
        self.tick(f"step {self.index} baseline")
        if b.cost < self.cost:
            self.kept_values, self.cost, self.held_gap = b.values, b.cost, b.held_gap
            self.kept_spans = _carried(self.kept_spans, b.values, b.spans)
            self.j_cost, self.j_held = b.judged_cost, b.judged_held_gap

    def screen(self, screen_base: Problem, remaining: list[str]) -> _StepState:
        """Step 1: every remaining effect fitted alone beside the kept ones, on the screening subset."""
        index, k = self.index, len(self.kept_names)
        current = with_parameters(self.base, self.kept_values)
        full = self.fit_problem.with_car(current)
        screen = screening_problem(full, self.screen_max_s)
        screen_cost = self.cost if screen is full else cost_of(screen, current)
        self.stage(f"step {index}: screening {len(remaining)} effects", len(remaining))
        screening = fit_all(screen, screen_cost, remaining, jobs=self.jobs, refine_top=0,
                            progress=lambda label: self.tick(f"step {index} {label}"))
        n_top = max(self.settings.refine_top if index == 1 else self.settings.refine_later, 1)
        ranked = sorted(screening, key=lambda r: (r.cost, self.order[r.effect]))
        best = ", ".join(f"{r.effect} ({r.improvement:.1%}, delta_BIC {r.delta_bic:.1f})" for r in ranked[:3])
        self.findings.add("screened", f"step {index}: screened {len(ranked)} effects; the best alone: {best}",
                          step=index, ranking=[{"effect": r.effect, "parameters": r.parameters,
                                                "improvement": r.improvement, "delta_bic": r.delta_bic}
                                               for r in ranked])
        return _StepState(index, k, screen_base, full, screen, screening, ranked, n_top,
                          bic(self.judge.fit, self.j_cost, k))

    def trial_of(self, st: _StepState, effect: str, o: Outcome) -> Trial:
        """A refit's figures as the step's tests see them."""
        return Trial(effect, o.values, o.cost, st.crit_now - bic(self.judge.fit, o.judged_cost, st.k + 1),
                     1.0 - o.judged_cost / self.j_cost if self.j_cost > 0 else 0.0, o.judged_held_gap,
                     o.evaluations, spans=o.spans)

    def decide(self, st: _StepState) -> tuple[Trial | None, list[Trial]]:
        """Steps 2-4: the best screened candidates refitted jointly in batches (then the gated later
        ones), tried in BIC order against the tests; the first that passes and passes again after
        :meth:`polish` is kept. Returns ``(the kept trial or None, every trial decided)``."""
        decided: list[Trial] = []
        chosen = None
        batches: list[list[FitResult]] = [st.ranked[:st.n_top]]
        gate_done = False
        while chosen is None:
            if not batches:  # every refitted candidate failed: step 4's later batches
                if gate_done:
                    break
                gate_done, later = True, self.gate(st)
                batches = [later[i:i + st.n_top] for i in range(0, len(later), st.n_top)]
                continue
            for tr in self.refit(st, batches.pop(0)):
                reason = _reject_reason(tr, self.j_held, *self.tests, self.settings.neutral_tol)
                if chosen is None and not reason:
                    tr, reason = self.polish(st, tr.effect)
                if chosen is None and not reason:
                    chosen = dataclasses.replace(tr, kept=True)
                    decided.append(chosen)
                else:
                    decided.append(dataclasses.replace(tr, reason=reason or BETTER))
        return chosen, decided

    def refit(self, st: _StepState, batch: list[FitResult]) -> list[Trial]:
        """Step 2: the batch's candidates refitted jointly with the kept effects, in BIC order."""
        self.stage(f"step {st.index}: joint refits of {', '.join(r.effect for r in batch)}", 1)
        outs = self.run([self.job(st.screen_base, self.kept_names + [r.effect],
                                  {**self.kept_values, **r.parameters}, r.effect) for r in batch])
        self.tick(f"step {st.index} joint refits")
        st.outcome.update((r.effect, o) for r, o in zip(batch, outs))
        trials = [self.trial_of(st, r.effect, o) for r, o in zip(batch, outs)]
        trials.sort(key=lambda tr: (-tr.delta_bic, self.order[tr.effect]))
        return trials

    def polish(self, st: _StepState, effect: str) -> tuple[Trial, str]:
        """Step 3's second refit of a candidate that passed: its figures and the tests' verdict."""
        o = st.outcome[effect]
        self.stage(f"step {st.index}: second refit of {effect}", 1)
        p, = self.run([self.job(st.screen_base, self.kept_names + [effect], o.values)])
        self.tick(f"step {st.index} second refit")
        if p.cost < o.cost:
            o = dataclasses.replace(p, spans=_carried(o.spans, p.values, p.spans))
        st.outcome[effect] = o = dataclasses.replace(o, evaluations=o.evaluations + p.evaluations)
        tr = self.trial_of(st, effect, o)
        return tr, (_reject_reason(tr, self.j_held, *self.tests, self.settings.neutral_tol)
                    or _report_held_reason(o.held_gap, self.held_gap))

    def gate(self, st: _StepState) -> list[FitResult]:
        """Step 4's later candidates: the gate is a test, judged where the tests judge (all fit
        windows, the step's normalisation), at each candidate's screened value."""
        rest = [r for r in st.ranked[st.n_top:] if r.improvement > 0.0]  # else screened at neutral
        if st.screen is st.full and self.judge.fit is self.fit_problem:  # the screening's own figures
            gains = [r.improvement for r in rest]
        else:
            gains = [1.0 - c / self.j_cost for c in self.costs(
                [(self.judge.fit, with_parameters(self.base, {**self.kept_values, **r.parameters})) for r in rest])]
        return [r for r, g in zip(rest, gains) if g >= self.tests[1] / self.settings.safety]

    def alike_of(self, chosen: Trial, others: list[Trial], outcome: dict[str, Outcome]) -> tuple[Alike, ...]:
        """The candidates of ``others`` the windows cannot tell from ``chosen`` (:class:`Alike`)."""
        if not others:
            return ()
        cars = [with_parameters(self.base, outcome[t.effect].values) for t in [chosen] + others]
        vals = self.values_per_window([(p, c) for c in cars for p in (self.judge.fit, self.judge.held)])
        per = [np.concatenate(vals[2 * i:2 * i + 2]) for i in range(len(cars))]
        out = []
        for t, v in zip(others, per[1:]):
            z = vuong_z(per[0], v)
            if abs(z) < self.settings.alike_z:
                out.append(Alike(t.effect, dict(outcome[t.effect].values), z, int(v.size)))
        return tuple(out)

    def keep(self, chosen: Trial, st: _StepState, decided: list[Trial]) -> None:
        """The chosen candidate joins the model; its runners-up are remembered for the exchanges."""
        self.kept_names.append(chosen.effect)
        self.kept_values = dict(chosen.parameters)
        self.kept_spans = _carried(self.kept_spans, chosen.parameters, chosen.spans)
        self.cost, self.held_gap = chosen.cost, st.outcome[chosen.effect].held_gap
        self.polished = True  # the next step's baseline is done
        self.runners_up[chosen.effect] = sorted((t for t in decided if not t.kept),
                                                key=lambda tr: (tr.cost,
                                                                self.order[tr.effect]))[:self.settings.refine_top]

    def max_exchanges_now(self) -> int:
        return self.settings.max_exchanges if len(self.kept_names) > 1 else 0

    def exchange(self, st: _StepState) -> bool:
        """Step 5: the best exchange of an earlier kept effect for a runner-up of its step, made;
        False when none helps."""
        swap = _best_exchange(self.run, st.screen_base, self.fit_problem, self.held_problem, self.judge,
                              self.base, st.index, self.kept_names, self.kept_values, self.cost, self.held_gap,
                              self.runners_up)
        if swap is None:
            return False
        self.swaps.append(swap)
        self.polished = False
        self.kept_names[self.kept_names.index(swap.out)] = swap.into
        self.runners_up[swap.into] = [t for t in self.runners_up.pop(swap.out) if t.effect != swap.into]
        self.kept_values, self.cost, self.held_gap = dict(swap.parameters), swap.cost_after, swap.held_gap_after
        self.kept_spans = _carried(self.kept_spans, swap.parameters, swap.spans)
        self.model_changed()
        self.findings.add("exchange", f"step {st.index}: exchanged {swap.out} for {swap.into}; held-out gap "
                                      f"{swap.held_gap_before:.3g} -> {swap.held_gap_after:.3g}",
                          step=st.index, out=swap.out, into=swap.into, parameters=dict(self.kept_values))
        return True

    # -- the backward check (step 8 of the module docstring) ------------------------------------
    def backward_check(self) -> None:
        """Every kept effect still earns its place: the weakest that would not is removed, and the
        check repeats."""
        while len(self.kept_names) > 1:
            self.stage(f"final check of {len(self.kept_names)} effects", 1)
            k = len(self.kept_names)
            outs = self.run([self.job(screening_problem(self.fit_problem, self.screen_max_s),
                                      [n for n in self.kept_names if n != e],
                                      {f: v for f, v in self.kept_values.items() if f != CANDIDATES[e].field})
                             for e in self.kept_names])
            self.tick("final check")
            weakest = None
            for e, o in zip(self.kept_names, outs):
                tr = Trial(e, dict(self.kept_values), self.cost,
                           bic(self.judge.fit, o.judged_cost, k - 1) - bic(self.judge.fit, self.j_cost, k),
                           1.0 - self.j_cost / o.judged_cost if o.judged_cost > 0 else 0.0, self.j_held,
                           o.evaluations)
                stay = _reject_reason(tr, o.judged_held_gap, *staying(*self.tests, self.settings.safety),
                                      self.settings.neutral_tol)
                reason = f"to stay: {stay}" if stay else _report_held_reason(self.held_gap, o.held_gap)
                if reason and (weakest is None or tr.delta_bic < weakest[0].delta_bic):
                    weakest = (dataclasses.replace(tr, reason=reason), o)
            if weakest is None:
                return
            tr, o = weakest
            self.pruned.append(tr)
            self.pruned_after.append(self.index)
            self.kept_names.remove(tr.effect)
            self.polished = False
            self.kept_values, self.cost, self.held_gap = o.values, o.cost, o.held_gap
            self.j_cost, self.j_held = o.judged_cost, o.judged_held_gap
            self.kept_spans = _carried(self.kept_spans, o.values, o.spans)
            self.model_changed()
            self.findings.add("removed", f"final check: removed {tr.effect} ({tr.reason})", effect=tr.effect,
                              reason=tr.reason, parameters=dict(self.kept_values))


def _values_text(values: dict[str, float], effect: str) -> str:
    """``field = value`` of ``effect``'s parameter among ``values``."""
    name = CANDIDATES[effect].field
    return f"{name} = {values[name]:.4g}" if name in values else "at neutral"


def _carried(spans: dict[str, tuple[float, float]], values: dict[str, float],
             new: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
    """The spans of a refit that set ``values``: its own (``new``), and an earlier refit's for a
    parameter it left inside that span."""
    out = {k: v for k, v in spans.items() if k in values and v[0] <= values[k] <= v[1]}
    out.update(new)
    return out


def renormalised(fit_problem: Problem, held_problem: Problem, car: CarDescription,
                 robust_factor: float) -> tuple[Judge, float]:
    """Step 6 of the module docstring: the problems normalised to ``car``'s residuals on the
    fit windows (the held-out windows never set a scale), and ``car``'s fit cost on that
    normalisation (from the same replay)."""
    res = segment_residuals(fit_problem, car)
    fit = rescaled(fit_problem, car, robust_factor, res=res)
    judge = Judge(fit, dataclasses.replace(held_problem, scales=fit.scales, robust_scale=fit.robust_scale))
    return judge, robust_total(window_costs(fit, res), fit.robust_scale)


def _best_exchange(run_jobs, screen_problem: Problem, fit_problem: Problem, held_problem: Problem, judge: Judge,
                   base: CarDescription, index: int, kept_names: list[str], kept_values: dict[str, float],
                   cost: float, held_gap: float, runners_up: dict[str, list[Trial]]) -> Swap | None:
    """The best exchange of step 5 of the module docstring (None when none lowers the fit
    cost without worsening the held-out gap). The last kept effect is not exchanged: its
    runners-up were refitted with the same others and lost."""
    pairs, tasks = [], []
    for out in kept_names[:-1]:
        start = {f: v for f, v in kept_values.items() if f != CANDIDATES[out].field}
        for tr in runners_up.get(out, ()):
            if tr.effect in kept_names:
                continue
            field = CANDIDATES[tr.effect].field
            names = [tr.effect if n == out else n for n in kept_names]
            pairs.append((out, tr.effect))
            tasks.append(RefitJob(screen_problem, fit_problem, held_problem, judge, base, tuple(names),
                                  {**start, field: tr.parameters[field]}, tr.effect))
    best = None
    for (out, into), o in zip(pairs, run_jobs(tasks) if tasks else []):
        if o.cost < cost and o.held_gap <= held_gap and (best is None or o.cost < best.cost_after):
            best = Swap(index, out, into, dict(o.values), cost, o.cost, held_gap, o.held_gap, dict(o.spans))
    return best


def staying(delta_bic_min: float, improvement_min: float, held_improvement_min: float,
            safety: float = SETTINGS.safety) -> tuple[float, float, float]:
    """The thresholds an effect already kept must still pass in the final check (step 8 of the
    module docstring): the entry thresholds without the calibration's ``safety`` factor."""
    return delta_bic_min / safety, improvement_min / safety, held_improvement_min / safety


def _report_held_reason(after: float, before: float) -> str:
    """Why a model whose held-out gap on the report's normalisation goes from ``before`` to
    ``after`` is not kept ("" when it does not grow): step 3's consistency test."""
    if math.isfinite(after) and after <= before:
        return ""
    change = f"{after / before - 1.0:+.1%}" if before > 0 and math.isfinite(after) else "not finite"
    return (f"held-out gap on the report's normalisation {change}: the held-out windows do not confirm it "
            "(it gains only on the step's weighting of the signals)")


def _reject_reason(tr: Trial, held_before: float, delta_bic_min: float, improvement_min: float,
                   held_improvement_min: float, neutral_tol: float = SETTINGS.neutral_tol) -> str:
    """Why ``tr`` is not kept ("" when it passes)."""
    value = tr.parameters[CANDIDATES[tr.effect].field]
    if neutral_offset(tr.effect, value) < neutral_tol:
        return f"fitted at its neutral value ({value:.4g}): no effect"
    if tr.delta_bic < delta_bic_min:
        return f"delta_BIC {tr.delta_bic:.1f} < {delta_bic_min:g} (fit windows)"
    if tr.improvement < improvement_min:
        return f"fit improvement {tr.improvement:.1%} < {improvement_min:.1%}"
    if not (math.isfinite(tr.held_gap) and tr.held_gap <= held_before * (1.0 - held_improvement_min)):
        if tr.held_gap == held_before:
            return ("held-out gap unchanged to the last digit: the held-out windows hold nothing it acts on "
                    "(a log with more of the manoeuvre it shows in can confirm it)")
        change = (f"{tr.held_gap / held_before - 1.0:+.1%}" if held_before > 0 and math.isfinite(tr.held_gap)
                  else "not finite")
        return (f"held-out gap {change}: not smaller by {held_improvement_min:.1%} "
                "(the held-out windows do not confirm it)")
    return ""


__all__ = ["Alike", "Chain", "Step", "Swap", "Trial", "vuong_z", "build_chain", "joint_refit", "staying",
           "with_parameters"]
