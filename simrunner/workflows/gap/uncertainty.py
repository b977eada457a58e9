"""How well the log pins each kept parameter: a standard error per parameter.

The chain's parameters minimise ``F(p) = sum_w f_w(p)``, the robust cost of the windows
``w`` they were fitted on (:func:`simrunner.workflows.gap.screening.screening_problem` of the fit
windows; each window restarts from the measured state, so the windows are the independent
units of the data). The covariance of such an estimate is taken from the spread of the fits
that leave one window out (the *jackknife*), each a Newton step from the fitted values:

    p_(-w) - p = -(H - H_w)^-1 (G - g_w),   cov = (n-1)/n sum_w (d_w - d)(d_w - d)^T + s s^T + b b^T

with ``H_w``, ``g_w`` window ``w``'s cost Hessian and gradient, ``H``, ``G`` their sums, ``d_w``
the left-out fit's step and ``d`` their mean. Where each window holds a small share of ``H``
this is the sandwich ``H^-1 B H^-1`` (``B`` the scores' spread); where a few windows pin a
parameter (a brake-before-reverse seen in the plan's two reversals, a deadband in its one
slow window) it is wider, as it must be: the sandwich then estimates ``B`` from a couple of
gradients and was measured 7-15 times too narrow on such parameters (bench/results/gap-history.md). It needs
no noise model: a window the model misses weighs in as much as the spread says, so model
error that differs from window to window widens the interval, while a bias common to all
windows (a nuisance the catalogue absorbs in a kept parameter) does not. ``s = -H^-1 G`` is
the Newton step from the fitted values to the minimum of the cost's quadratic model over the
stencil: the fit's own distance from the minimum it was after (its tolerance, a cost that
moves in steps such as a latency's control sub-steps), kept inside the fit range and added in
quadrature.

Two biases every window shares are estimated and added the same way, since the spread cannot
show them. ``b`` is the fits' physics step (``Problem.dt_s``, 5 ms): the cost's gradient again
at half the step gives where the minimum moves, ``d = -H^-1 (G_half - G)``; the step's error
is of first order in the step, so the minimum at step zero lies ``b = 2 d`` away (Richardson's
estimate; a steering lag fitted 3 ms short at 5 ms, as a 1-ms replay shows, and a steering
rate limit 4.5 of its standard errors high, bench/results/gap-history.md). And a time that acts at whole control
sub-steps (:data:`SUBSTEP_TIMES`: the command latency's queue and the ESC's hold are checked
there, ``simrunner.car.effects.control_steps``) cannot be told apart within one: a variance
of ``sub-step^2 / 12`` (uniform over it) is added to its own.

Derivatives by central differences in the fit's ``[0, 1]``-scaled coordinates (the fit
ranges of :data:`simrunner.workflows.gap.fit.CANDIDATES`, log-scaled where the fit searches
in log), with a step of ``settings.uncertainty_step`` (5 % of the range: latencies act in whole control
sub-steps of 4-5 ms, so a much smaller step would see a staircase). The stencil (the centre,
``+-h`` along each parameter and the four corners of each pair: ``1 + 2k + 2k(k-1)``
replays) is moved inside the range for a parameter near its bound, and each window's
gradient carried back to the parameter by its own Hessian. ``sigma`` is ``nan`` for a
parameter along which the cost does not curve upward (``H_ii <= 0``: the log does not pin
it), for one at an end of its fit range (``Candidate.at_bound``: the bound, not the cost,
made that minimum, and the report warns of it; DS3's pose-only rolling resistance at 0.1
turned ``H`` indefinite and took every other sigma with it), and for one that a single
window pins (``H - H_w`` not positive definite: without that window the log would not pin
it; :attr:`Uncertainty.one_window` names the window), and the others' are those with it held;
all are ``nan`` when the rest of ``H`` is not positive definite either. It says nothing about
a bias of the catalogue effect standing in for something else, nor about car-file numbers
that are off (docs/gap.md, "Known limits").
"""
from __future__ import annotations

import itertools
import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from simrunner.car.effects import control_steps
from simrunner.workflows.gap.chain import _bounds01, with_parameters
from simrunner.workflows.gap.fit import CANDIDATES, Problem, _quiet_worker, window_values, window_values_task
from vehicle.description import CarDescription

# ``Effects`` fields that act at whole control sub-steps (simrunner.car.effects): resolved to one
SUBSTEP_TIMES = ("command_latency_s", "esc_reverse_delay_s")


def _dvalue_du(names: Sequence[str], u: np.ndarray) -> np.ndarray:
    """d value / d u of each parameter at ``u``, in the fit's ``[0, 1]`` coordinates
    (``chain._bounds01``: linear in the value, or in its log where the fit searches in log)."""
    out = []
    for c, x in zip((CANDIDATES[n] for n in names), u):
        lo, hi = c.to_x(c.lo), c.to_x(c.hi)
        out.append((hi - lo) * (c.from_x(lo + x * (hi - lo)) if c.log_scale else 1.0))  # d exp(x)/dx = exp(x)
    return np.array(out)


@dataclass(frozen=True)
class Uncertainty:
    """:func:`parameter_uncertainty`'s answer, by ``Effects`` field."""

    sigma: dict[str, float]  # the standard error (nan: not known; the module docstring)
    one_window: dict[str, int] = field(default_factory=dict)  # parameters one window alone pins: its index


def _stencil(c: np.ndarray, step: float) -> list[np.ndarray]:
    """The centre, ``+-step`` along each coordinate, the four corners of each pair."""
    k = len(c)
    points = [c.copy()]
    for i in range(k):
        for s in (1.0, -1.0):
            p = c.copy()
            p[i] += s * step
            points.append(p)
    for i, j in itertools.combinations(range(k), 2):
        for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            p = c.copy()
            p[i] += si * step
            p[j] += sj * step
            points.append(p)
    return points


def _window_derivatives(f: np.ndarray, k: int, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Each window's gradient ``(n, k)`` and Hessian ``(n, k, k)`` at the stencil's centre from
    its costs ``f`` (``(points, n)``, the points in :func:`_stencil`'s order)."""
    n = f.shape[1]
    f0 = f[0]
    grad = np.empty((n, k))
    hess = np.empty((n, k, k))
    for i in range(k):
        plus, minus = f[1 + 2 * i], f[2 + 2 * i]
        grad[:, i] = (plus - minus) / (2.0 * step)
        hess[:, i, i] = (plus - 2.0 * f0 + minus) / step ** 2
    corner = 1 + 2 * k
    for i, j in itertools.combinations(range(k), 2):
        pp, pm, mp, mm = f[corner:corner + 4]
        corner += 4
        hess[:, i, j] = hess[:, j, i] = (pp - pm - mp + mm) / (4.0 * step ** 2)
    return grad, hess


def _positive_definite(a: np.ndarray) -> bool:
    try:
        np.linalg.cholesky(a)
    except np.linalg.LinAlgError:
        return False
    return True


def covariance_u(grad: np.ndarray, hess: np.ndarray, u: np.ndarray, pinned: list[int],
                 grad_half: np.ndarray | None = None) -> tuple[np.ndarray | None, list[int], dict[int, int]]:
    """``(cov, kept, one_window)``: the module docstring's covariance (in ``u``) of the
    parameters ``kept`` (``pinned`` but those one window alone pins, ``one_window``: parameter
    -> that window), from the windows' gradients ``grad`` and Hessians ``hess`` at ``u``, and
    (for the physics step's term ``b b^T``) their gradients ``grad_half`` at half the step;
    ``cov`` None when their ``H`` is not positive definite."""
    h_all = hess.sum(axis=0)
    kept = list(pinned)
    if not kept or not _positive_definite(h_all[np.ix_(kept, kept)]):
        return None, kept, {}
    one_window: dict[int, int] = {}
    while kept:  # drop, one at a time, a parameter that only one window pins
        idx = np.ix_(kept, kept)
        lone = next((w for w in range(len(hess)) if not _positive_definite(h_all[idx] - hess[w][idx])), None)
        if lone is None:
            break
        share = np.diag(hess[lone])[kept] / np.diag(h_all)[kept]
        i = kept[int(np.argmax(share))]
        one_window[i] = lone
        kept.remove(i)
    if not kept:
        return None, kept, one_window
    idx = np.ix_(kept, kept)
    h, g = h_all[idx], grad[:, kept]
    n = len(g)
    total = g.sum(axis=0)
    left_out = np.array([-np.linalg.solve(h - hess[w][idx], total - g[w]) for w in range(n)])
    spread = left_out - left_out.mean(axis=0)
    newton = np.clip(u[kept] - np.linalg.solve(h, total), 0.0, 1.0) - u[kept]  # to the minimum within the range
    cov = spread.T @ spread * (n - 1) / n + np.outer(newton, newton)
    if grad_half is not None:  # Richardson: twice the move of the minimum from the step to half of it
        b = np.clip(u[kept] - 2.0 * np.linalg.solve(h, grad_half[:, kept].sum(axis=0) - total), 0.0, 1.0) - u[kept]
        cov += np.outer(b, b)
    return cov, kept, one_window


def parameter_uncertainty(problem: Problem, base: CarDescription, names: Sequence[str], values: dict[str, float],
                          *, jobs: int = 1, step: float | None = None) -> Uncertainty:
    """The standard error of each parameter of ``values`` (the ``Effects`` fields of the
    effects ``names``, fitted on ``problem``'s windows with ``base`` as the car): the module
    docstring's jackknife with its two shared biases, and the parameters one window alone
    pins. ``problem`` needs ``dt_s`` and ``with_step`` (:class:`~simrunner.workflows.gap.fit.Problem`);
    ``step`` default: its ``settings.uncertainty_step``."""
    names = list(names)
    if step is None:
        step = problem.settings.uncertainty_step
    k = len(names)
    if not k:
        return Uncertainty({})
    to_u, from_u = _bounds01(names)
    u = to_u(values)
    c = np.clip(u, step, 1.0 - step)  # the stencil's centre, inside the range
    cars = [with_parameters(base, {**values, **from_u(p)}) for p in _stencil(c, step)]
    half = problem.with_step(problem.dt_s / 2.0)
    tasks = [(problem, car) for car in cars] + [(half, car) for car in cars[1:1 + 2 * k]]  # +-step at half
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs, initializer=_quiet_worker) as pool:
            f_all = np.array(list(pool.map(window_values_task, tasks)))
    else:
        f_all = np.array([window_values(p, car) for p, car in tasks])
    f, f_half = f_all[:len(cars)], f_all[len(cars):]
    fields = [CANDIDATES[m].field for m in names]
    out = {fd: math.nan for fd in fields}
    if f.shape[1] < 2 or not np.isfinite(f).all():
        return Uncertainty(out)
    grad, hess = _window_derivatives(f, k, step)
    grad += hess @ (u - c)  # each window's gradient carried from the centre to the parameters
    grad_half = None  # (a replay that failed at half the step leaves that term out)
    if np.isfinite(f_half).all():
        grad_half = (f_half[0::2] - f_half[1::2]).T / (2.0 * step) + hess @ (u - c)
    h_all = hess.sum(axis=0)
    # the others: the cost does not curve along them, or the fit stopped at a bound (a minimum
    # the bound makes, not the cost's curvature)
    pinned = [i for i in range(k)
              if h_all[i, i] > 0.0 and not CANDIDATES[names[i]].at_bound(values[fields[i]], problem.settings)]
    cov_u, kept, lone = covariance_u(grad, hess, u, pinned, grad_half)
    if cov_u is not None:
        var = np.maximum(np.diag(cov_u), 0.0) * _dvalue_du(names, u)[kept] ** 2
        substep_s = control_steps(problem.dt_s) * problem.dt_s
        var += [substep_s ** 2 / 12.0 if fields[i] in SUBSTEP_TIMES else 0.0 for i in kept]
        out.update({fields[i]: float(s) for i, s in zip(kept, np.sqrt(var))})
    return Uncertainty(out, {fields[i]: w for i, w in lone.items()})


def parameter_sigma(problem: Problem, base: CarDescription, names: Sequence[str], values: dict[str, float],
                    *, jobs: int = 1, step: float | None = None) -> dict[str, float]:
    """:attr:`Uncertainty.sigma` of :func:`parameter_uncertainty` (``{}`` for no parameter)."""
    return parameter_uncertainty(problem, base, names, values, jobs=jobs, step=step).sigma


__all__ = ["Uncertainty", "parameter_uncertainty", "parameter_sigma", "covariance_u", "window_values",
           "SUBSTEP_TIMES"]
