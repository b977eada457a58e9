"""Fitting catalogue effects by simulation: the problem, its cost, one-parameter fits, screening.

Each candidate effect has one parameter (a field of ``vehicle.description.Effects``). It is fitted
by simulation: the objective is the sum over the fit windows and the signals of
:data:`simrunner.workflows.gap.replay.FIT_SIGNALS` of squared residuals, each signal normalised by
its RMS under the nominal model (floored at :data:`SCALE_FLOOR`), so every signal weighs
the same before fitting. Search: a coarse grid over the bounds (``settings.grid_points``, the
car's current value counts as known), then bounded Brent
(``scipy.optimize.minimize_scalar``) in the bracket around the best grid point; the best
point evaluated wins.

Robust window cost: real logs have windows the catalogue cannot follow at all (a slide, a
touch of a wall, a hand on the car, a sensor hiccup too small to be a glitch); in a plain
sum of squares a few of them outweigh every other window, and an effect that bends those
few at the expense of the rest wins the fit and then fails on held-out data. So each
window's sum of squares ``c_w`` (``n_w`` compared values) enters through the Cauchy loss
``c0_w ln(1 + c_w / c0_w)`` with ``c0_w = robust_scale * n_w``; ``run_gap`` sets
``robust_scale`` to ``settings.robust_window_factor`` times the median mean square per value of
the nominal model's fit windows (:func:`robust_scale_of`), so a window well below that
counts as in least squares and one 50 times the median counts about 10 times, not 50.
``robust_scale = inf`` is the plain sum of squares.

Ranking: Bayesian information criterion on the normalised residuals,

    BIC = n_eff * ln(cost / n) + k * ln(n_eff)

with ``n`` compared values, ``k`` fitted parameters (0 for the nominal model, 1 per effect)
and ``n_eff`` the effective number of independent values, ``settings.n_eff_per_s`` per second of
fit windows per signal (residuals within a window are strongly correlated, so ``n`` would
overstate the evidence). Lower is better; ``delta_bic = BIC_nominal - BIC_effect``.

Acceptance (:mod:`simrunner.workflows.gap.chain` applies it at every step of the chain,
with a held-out test on top): an effect passes only if ``delta_bic >= settings.delta_bic_min`` and
its relative cost reduction ``improvement >= settings.improvement_min``. The two thresholds are
calibrated on effect-free synthetic logs by
:mod:`simrunner.workflows.gap.thresholds` (see docs/gap.md for the run that produced them).

Fits run in worker processes (``jobs``); dartpy worlds are built inside each worker. A fit
depends only on its inputs, so results are identical for any ``jobs``.
"""
from __future__ import annotations

import dataclasses
import math
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy.optimize import minimize_scalar

from simrunner.telemetry.log import RunLog
from simrunner.workflows.gap import GapError
from simrunner.workflows.gap.logs import Derived
from simrunner.workflows.gap.replay import (FIT_SIGNALS, SimFactory, Window, default_sim_factory,
                                  replay, residuals, window_mask)
from simrunner.workflows.gap.settings import SETTINGS, GapSettings
from vehicle.description import CarDescription


def scale_floor(settings: GapSettings, signal: str) -> float:
    """The smallest normalisation of a residual signal (``settings.scale_floor_*``)."""
    return {"along_m": settings.scale_floor_position_m, "cross_m": settings.scale_floor_position_m,
            "yaw_rad": settings.scale_floor_yaw_rad, "speed_mps": settings.scale_floor_speed_mps,
            "yaw_rate_radps": settings.scale_floor_yaw_rate_radps}[signal]


@dataclass(frozen=True)
class Candidate:
    """One catalogue effect as a fit: its ``Effects`` field and search bounds."""

    name: str
    field: str
    lo: float
    hi: float
    log_scale: bool = False  # search in log(value) (for positive parameters spanning decades)

    def to_x(self, v: float) -> float:
        return math.log(v) if self.log_scale else v

    def from_x(self, x: float) -> float:
        return math.exp(x) if self.log_scale else x

    def u(self, v: float) -> float:
        """Where ``v`` lies in the fit range, ``[0, 1]`` in the search's scale (clipped)."""
        lo, hi = self.to_x(self.lo), self.to_x(self.hi)
        return (self.to_x(min(max(v, self.lo), self.hi)) - lo) / (hi - lo)

    def at_bound(self, v: float, settings: GapSettings = SETTINGS) -> bool:
        """``v`` within ``settings.at_bound_u`` of an end of the fit range: the fit wanted to go further."""
        u = self.u(v)
        return u <= settings.at_bound_u or u >= 1.0 - settings.at_bound_u


def _candidates() -> dict[str, Candidate]:
    """One candidate per ``simrunner.car.effects.EFFECTS`` entry, with its fit bounds and
    search scale (``EffectSpec.log_scale``: limits absent from the nominal model, such as the
    steering rate limit and the top speed, and the drive-limit factors, which span decades)."""
    from simrunner.car.effects import EFFECTS

    out = {}
    for spec in EFFECTS.values():
        if len(spec.params) != 1:  # pragma: no cover - the catalogue has one parameter each
            raise GapError(f"effect {spec.name}: expected one parameter (got {len(spec.params)})")
        (lo, hi), = spec.bounds
        out[spec.name] = Candidate(spec.name, spec.param, float(lo), float(hi),
                                   log_scale=spec.log_scale)
    return out


CANDIDATES: dict[str, Candidate] = _candidates()


def with_effect(car: CarDescription, name: str, value: float) -> CarDescription:
    """``car`` with the parameter of effect ``name`` set to ``value``."""
    eff = dataclasses.replace(car.effects, **{CANDIDATES[name].field: float(value)})
    return car.replace(effects=eff)


@dataclass(frozen=True)
class Segment:
    """One log's share of a problem: the log, its smoothed states and the windows used."""

    log: RunLog
    derived: Derived
    windows: tuple[Window, ...]

    @property
    def duration_s(self) -> float:
        t = self.log.t_s
        return float(sum(t[w.stop - 1] - t[w.start] for w in self.windows))

    @property
    def n_samples(self) -> int:
        return int(window_mask(len(self.log), self.windows).sum())


class ResidualMemo:
    """The residuals (:func:`segment_residuals`) a problem already computed in this process, by
    car and replay set-up: the chain and the fits ask for the same car more than once (a
    fit's best value again by the joint refit, a trial's winner by the next step, the
    nominal model by several steps); a replay is deterministic, so the answer is the same
    and need not be simulated again. Shared by the problems ``dataclasses.replace`` makes
    from one (other scales, car or step: the key holds what the residuals depend on);
    least recently used entries go beyond ``max_values`` stored floats. Pickled empty (a
    worker process starts its own). The residual arrays are shared, so they are read-only."""

    def __init__(self, max_values: int = 4_000_000):
        self.max_values = max_values
        self._entries: dict = {}  # key -> (segments (kept alive: the key holds their id), residuals, size)
        self._values = 0

    def __reduce__(self):
        return ResidualMemo, (self.max_values,)

    def residuals(self, problem: "Problem", car: CarDescription, compute: Callable[[], list]) -> list:
        """``compute()``'s answer for ``(problem, car)``, computed once."""
        # repr: floats round-trip exactly and -0.0 stays apart from 0.0 (== would merge them)
        key = (repr(car), id(problem.segments), problem.dt_s, problem.sim_factory, problem.settings)
        try:
            hit = self._entries.pop(key, None)
        except TypeError:  # an unhashable sim_factory: no memo
            return compute()
        if hit is None:
            res = compute()
            for r in res:  # shared with every later caller: read-only, so none can change another's
                for v in r.values():
                    v.setflags(write=False)
            hit = (problem.segments, res, sum(v.size for r in res for v in r.values()))
            self._values += hit[2]
        self._entries[key] = hit  # now the most recently used
        while self._values > self.max_values and len(self._entries) > 1:
            oldest = next(iter(self._entries))
            self._values -= self._entries.pop(oldest)[2]
        return hit[1]


@dataclass(frozen=True)
class Problem:
    """Everything a fit needs (picklable: sent to worker processes): the car the candidate
    parameters are set on, the windows of one or several logs of that car, the residual
    signals compared (those every log supports) and their normalisation."""

    car: CarDescription
    segments: tuple[Segment, ...]
    scales: dict[str, float]
    signals: tuple[str, ...] = FIT_SIGNALS
    dt_s: float = SETTINGS.workflow_dt_s
    sim_factory: SimFactory = default_sim_factory
    robust_scale: float = math.inf  # Cauchy scale per compared value (module docstring); inf: least squares
    settings: GapSettings = SETTINGS  # the workflow's thresholds for this problem's fits
    memo: ResidualMemo = field(default_factory=ResidualMemo, compare=False, repr=False)  # replays done

    @property
    def n_values(self) -> int:
        return sum(s.n_samples for s in self.segments) * len(self.signals)

    @property
    def n_eff(self) -> float:
        dur = sum(s.duration_s for s in self.segments)
        return max(self.settings.n_eff_per_s * dur * len(self.signals), 2.0)

    def with_car(self, car: CarDescription) -> "Problem":
        return dataclasses.replace(self, car=car)

    def with_step(self, dt_s: float) -> "Problem":
        """The same windows replayed at the physics step ``dt_s``."""
        return dataclasses.replace(self, dt_s=dt_s)

    def window_places(self) -> list[tuple[str, float, float]]:
        """``(log source, first stamp s, last stamp s)`` of each window, in the order of
        :func:`window_values`."""
        return [(seg.log.source, float(seg.log.t_s[w.start]), float(seg.log.t_s[w.stop - 1]))
                for seg in self.segments for w in seg.windows]


def segment_residuals(problem: Problem, car: CarDescription) -> list[dict[str, np.ndarray]]:
    """Residuals of ``car`` on each segment's windows (NaN elsewhere), per log (computed once
    per problem and car: :class:`ResidualMemo`)."""
    return problem.memo.residuals(problem, car, lambda: _segment_residuals(problem, car))


def _segment_residuals(problem: Problem, car: CarDescription) -> list[dict[str, np.ndarray]]:
    out = []
    for seg in problem.segments:
        pred = replay(car, seg.log, seg.derived, seg.windows, dt_s=problem.dt_s,
                      sim_factory=problem.sim_factory, settings=problem.settings)
        out.append(residuals(seg.log, seg.derived, pred))
    return out


def window_costs(problem: Problem, res: Sequence[dict[str, np.ndarray]]) -> list[tuple[float, int]]:
    """``(c_w, n_w)`` per window of ``problem`` (segment by segment): the sum of squared
    normalised residuals over the problem's signals and the number of values compared
    (``res``: one residual dict per segment; a non-finite residual, a diverged simulation,
    counts as 1e3 scales)."""
    out = []
    for seg, r in zip(problem.segments, res):
        for w in seg.windows:
            c, n = 0.0, 0
            for s in problem.signals:
                v = r[s][w.start:w.stop] / problem.scales[s]
                v = np.where(np.isfinite(v), v, 1e3)
                c += float(np.dot(v, v))
                n += v.size
            out.append((c, n))
    return out


def robust_total(costs: Sequence[tuple[float, int]], robust_scale: float) -> float:
    """Sum over windows of ``c0_w ln(1 + c_w / c0_w)``, ``c0_w = robust_scale * n_w``
    (the plain sum of ``c_w`` when ``robust_scale`` is infinite)."""
    if not math.isfinite(robust_scale):
        return float(sum(c for c, _ in costs))
    total = 0.0
    for c, n in costs:
        c0 = robust_scale * max(n, 1)
        total += c0 * math.log1p(c / c0)
    return total


def robust_scale_of(costs: Sequence[tuple[float, int]], factor: float = SETTINGS.robust_window_factor) -> float:
    """``settings.robust_window_factor`` (``factor``) times the median over windows of ``c_w / n_w``
    (the nominal model's, when called by ``run_gap``); inf for no windows or ``factor = inf``."""
    per_value = [c / n for c, n in costs if n > 0]
    if not per_value or not math.isfinite(factor):
        return math.inf
    return max(factor * float(np.median(per_value)), 1e-12)


def window_values(problem: Problem, car: CarDescription) -> np.ndarray:
    """``(W,)``: each window's contribution to :func:`cost_of` (its robust loss,
    :func:`robust_total` of that window alone)."""
    costs = window_costs(problem, segment_residuals(problem, car))
    return np.array([robust_total([cw], problem.robust_scale) for cw in costs])


def window_values_task(args: tuple[Problem, CarDescription]) -> np.ndarray:
    """:func:`window_values` of ``(problem, car)``, for a process pool."""
    problem, car = args
    return window_values(problem, car)


def cost_of(problem: Problem, car: CarDescription) -> float:
    """The cost of ``car`` on the problem's windows: the sum of squared normalised residuals,
    each window through the robust loss of the module docstring."""
    return robust_total(window_costs(problem, segment_residuals(problem, car)), problem.robust_scale)


def nominal_scales(segments: Sequence[Segment], res: Sequence[dict[str, np.ndarray]],
                   signals: Sequence[str] = FIT_SIGNALS, settings: GapSettings = SETTINGS) -> dict[str, float]:
    """Per-signal normalisation: RMS of the nominal residuals in the segments' windows, floored."""
    out = {}
    for s in signals:
        parts = [r[s][window_mask(len(seg.log), seg.windows) & np.isfinite(r[s])]
                 for seg, r in zip(segments, res)]
        v = np.concatenate(parts) if parts else np.zeros(0)
        out[s] = max(float(np.sqrt(np.mean(v * v))) if v.size else 0.0, scale_floor(settings, s))
    return out


def rescaled(problem: Problem, car: CarDescription, robust_factor: float | None = None,
             res: Sequence[dict[str, np.ndarray]] | None = None) -> Problem:
    """``problem`` normalised to ``car``'s residuals on its windows (:func:`nominal_scales`
    and :func:`robust_scale_of` with ``car`` in the nominal model's place; a least-squares
    problem stays one): every signal weighs the same again under ``car``, as every signal
    weighs the same under the nominal model before the first fit. ``res``: ``car``'s
    residuals on the problem (:func:`segment_residuals`), when the caller has them.
    ``robust_factor`` default: the problem's ``settings.robust_window_factor``."""
    res = segment_residuals(problem, car) if res is None else res
    if robust_factor is None:
        robust_factor = problem.settings.robust_window_factor
    out = dataclasses.replace(problem, scales=nominal_scales(problem.segments, res, problem.signals, problem.settings),
                              robust_scale=math.inf)
    if math.isfinite(problem.robust_scale):
        out = dataclasses.replace(out, robust_scale=robust_scale_of(window_costs(out, res), robust_factor))
    return out


def bic(problem: Problem, cost: float, k: int) -> float:
    n_eff = problem.n_eff
    return n_eff * math.log(max(cost, 1e-300) / problem.n_values) + k * math.log(n_eff)


@dataclass(frozen=True)
class FitResult:
    """One fitted effect; ``parameters`` maps the ``Effects`` field to the fitted value."""

    effect: str
    parameters: dict[str, float]
    cost: float
    criterion: float  # BIC (lower is better)
    delta_bic: float  # BIC_nominal - BIC (positive = better than nominal)
    improvement: float  # 1 - cost / cost_nominal on the fit windows
    evaluations: int
    trace: tuple[tuple[float, float], ...] = field(default=(), repr=False)  # (value, cost) evaluated
    refined: bool = True  # False: screened out after the grid (coarse value)

    def to_json(self) -> dict:
        return {"effect": self.effect, "parameters": self.parameters, "cost": self.cost,
                "bic": self.criterion, "delta_bic": self.delta_bic, "improvement": self.improvement,
                "evaluations": self.evaluations, "refined": self.refined}


def fit_effect(problem: Problem, name: str, nominal_cost: float, *, refine: bool = True,
               known: Sequence[tuple[float, float]] = ()) -> FitResult:
    """Fit effect ``name`` on ``problem``: grid, then (``refine``) bounded Brent around the
    best grid point; ``known`` (value, cost) pairs are not evaluated again."""
    cand, settings = CANDIDATES[name], problem.settings
    current = float(getattr(problem.car.effects, cand.field))
    seen: dict[float, float] = dict(known)
    if cand.lo <= current <= cand.hi:
        seen[current] = nominal_cost

    def f(x: float) -> float:
        v = float(np.clip(cand.from_x(x), cand.lo, cand.hi))
        if v not in seen:
            seen[v] = cost_of(problem, with_effect(problem.car, name, v))
        return seen[v]

    xs = np.linspace(cand.to_x(cand.lo), cand.to_x(cand.hi), settings.grid_points)
    costs = [f(x) for x in xs]
    probe = _probe(xs, costs, settings.end_probe_fraction)
    f(probe)
    other = _other_side(xs, costs, probe)
    if other is not None:
        f(other)
    if refine:
        k = int(np.argmin(costs))
        a, b = xs[max(k - 1, 0)], xs[min(k + 1, settings.grid_points - 1)]
        span = cand.to_x(cand.hi) - cand.to_x(cand.lo)
        minimize_scalar(f, bounds=(a, b), method="bounded",
                        options={"xatol": 2e-3 * span, "maxiter": settings.brent_maxiter})
    best_v = min(seen, key=lambda v: (seen[v], v))
    best_cost = seen[best_v]
    crit = bic(problem, best_cost, 1)
    return FitResult(name, {cand.field: best_v}, best_cost, crit, bic(problem, nominal_cost, 0) - crit,
                     1.0 - best_cost / nominal_cost if nominal_cost > 0 else 0.0, len(seen),
                     tuple(sorted(seen.items())), refined=refine)


def _probe(xs: np.ndarray, costs: Sequence[float], end_probe_fraction: float = SETTINGS.end_probe_fraction) -> float:
    """One extra screening point: the vertex of the parabola through the best grid point
    and its neighbours (three points at an end of the grid), kept within the neighbours;
    the midpoint towards the better neighbour if the parabola is not convex. This finds
    a small deviation from neutral that falls between grid points (e.g. a gain of 1.07
    on a 0.25 grid).

    When the best grid point is an end of the grid (the neutral value of a latency, a lag,
    a play...), the probe goes at least ``end_probe_fraction`` of the way towards its
    neighbour: a small value there can sit in a narrow valley (a 12-ms latency on a 50-ms
    grid: its cost at 50 ms is far above the neutral one, the parabola's vertex falls
    outside the bounds, and a probe at the end itself would screen the latency at 0 %)."""
    k = int(np.argmin(costs))
    lo, hi = xs[max(k - 1, 0)], xs[min(k + 1, len(xs) - 1)]
    if k == 0:  # best at an end: the probe goes at least end_probe_fraction of the way inside
        lo = xs[0] + end_probe_fraction * (xs[1] - xs[0])
    elif k == len(xs) - 1:
        hi = xs[-1] - end_probe_fraction * (xs[-1] - xs[-2])
    j = min(max(k, 1), len(xs) - 2)
    x0, x1, x2 = xs[j - 1], xs[j], xs[j + 1]
    c0, c1, c2 = costs[j - 1], costs[j], costs[j + 1]
    den = (x1 - x0) * (c1 - c2) - (x1 - x2) * (c1 - c0)
    if den != 0.0:
        num = (x1 - x0) ** 2 * (c1 - c2) - (x1 - x2) ** 2 * (c1 - c0)
        vertex = x1 - 0.5 * num / den
        if c0 - 2.0 * c1 + c2 > 0.0 and np.isfinite(vertex):  # convex (uniform grid)
            return float(min(max(vertex, lo), hi))
    nb = [i for i in (k - 1, k + 1) if 0 <= i < len(xs)]
    better = min(nb, key=lambda i: costs[i])
    return float(0.5 * (xs[k] + xs[better]))


def _other_side(xs: np.ndarray, costs: Sequence[float], probe: float) -> float | None:
    """A second screening point when the best grid point is inside the grid: the midpoint
    towards the neighbour on the other side of :func:`_probe`'s (towards the worse
    neighbour when the probe is the best point itself). A limit (a friction scale, a top
    speed) is flat on one side of its true value and steep on the other: the parabola then
    puts its vertex on the flat side and the valley next to the steep side goes unseen (a
    friction scale of 0.67 on the grid 0.6, 0.9, 1.2: costs 1020, 432, 445, vertex at 1.04;
    at 0.75 the cost is 325, at 0.67 229; screened at 0.9, 0.5 %, the chain never refitted
    it). None at an end of the grid (:func:`_probe` goes inside already)."""
    k = int(np.argmin(costs))
    if k == 0 or k == len(xs) - 1:
        return None
    if probe > xs[k]:
        side = k - 1
    elif probe < xs[k]:
        side = k + 1
    else:
        side = max((k - 1, k + 1), key=lambda i: costs[i])
    return float(0.5 * (xs[k] + xs[side]))


def _quiet_worker() -> None:
    """Worker initialiser: send the C++ engine's warnings (stderr, fd 2) to /dev/null so they
    do not garble the parent's progress bar; results and exceptions come back pickled. The
    worker ends with the process that started it (killed by SIGKILL, it would finish its fit
    and then wait for work for ever: it holds both ends of its queue's pipe)."""
    import os

    from simrunner.run.supervise import die_with_parent

    die_with_parent()
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 2)
    os.close(devnull)


def _fit_task(args) -> FitResult:
    problem, name, nominal_cost, refine, known = args
    return fit_effect(problem, name, nominal_cost, refine=refine, known=known)


def fit_all(problem: Problem, nominal_cost: float, effects: Sequence[str] | None = None, *, jobs: int = 2,
            progress: Callable[[str], None] | None = None, refine_top: int | None = None) -> list[FitResult]:
    """Fit every effect in ``effects`` (default: all of :data:`CANDIDATES`) and return them
    ranked by criterion (ties by catalogue order).

    Two stages: every effect on its grid (screening), then the ``refine_top`` best (by grid
    cost) refined by Brent; the others keep their best grid value (``refined`` False).
    ``jobs`` worker processes (1 = in this process); ``progress(label)`` is called as each
    fit finishes (``len(effects) + min(refine_top, len(effects))`` calls); ``refine_top`` default: the
    problem's ``settings.refine_top``."""
    if refine_top is None:
        refine_top = problem.settings.refine_top
    names = list(CANDIDATES) if effects is None else list(effects)
    unknown = [n for n in names if n not in CANDIDATES]
    if unknown:
        raise GapError(f"unknown effect(s) {', '.join(unknown)} (expected some of {', '.join(CANDIDATES)})")
    order = {n: i for i, n in enumerate(CANDIDATES)}
    pool = (ProcessPoolExecutor(max_workers=jobs, initializer=_quiet_worker)
            if jobs > 1 and len(names) > 1 else None)

    def run(tasks, label):
        out: dict[str, FitResult] = {}
        if pool is None:
            for t in tasks:
                out[t[1]] = _fit_task(t)
                if progress:
                    progress(f"{label} {t[1]}")
        else:
            futures = {pool.submit(_fit_task, t): t[1] for t in tasks}
            for fut in as_completed(futures):
                out[futures[fut]] = fut.result()
                if progress:
                    progress(f"{label} {futures[fut]}")
        return out

    try:
        results = run([(problem, n, nominal_cost, False, ()) for n in names], "screen")
        top = sorted(results.values(), key=lambda r: (r.cost, order[r.effect]))[:max(refine_top, 0)]
        results.update(run([(problem, r.effect, nominal_cost, True, r.trace) for r in top], "refine"))
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)  # all done, or a stop (Ctrl-C, the budget) in between
    return sorted(results.values(), key=lambda r: (r.criterion, order[r.effect]))
