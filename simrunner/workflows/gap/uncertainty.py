"""How well the log pins each kept parameter: a standard error per parameter.

The chain's parameters minimise ``F(p) = sum_w f_w(p)``, the robust cost of the windows
``w`` they were fitted on (:func:`simrunner.workflows.gap.chain.screening_problem` of the fit
windows; each window restarts from the measured state, so the windows are the independent
units of the data). The covariance of such an estimate is the *sandwich*

    cov = H^-1 B H^-1 + d d^T,   H = the Hessian of F,   B = n/(n-1) sum_w (g_w - g)(g_w - g)^T

with ``g_w`` the gradient of window ``w``'s cost and ``g`` their mean (the scores, centred:
the optimiser stops near, not at, the minimum). It needs no noise model: a window the model
misses weighs in as much as the spread of its gradient says, so model error that differs
from window to window widens the interval, while a bias common to all windows (a nuisance
the catalogue absorbs in a kept parameter) does not. ``d = -H^-1 sum_w g_w`` is the Newton
step from the fitted values to the minimum of the cost's quadratic model over the stencil:
the fit's own distance from the minimum it was after (its tolerance, a cost that moves in
steps such as a latency's control sub-steps), kept inside the fit range and added in
quadrature.

Derivatives by central differences in the fit's ``[0, 1]``-scaled coordinates (the fit
ranges of :data:`simrunner.workflows.gap.fit.CANDIDATES`, log-scaled where the fit searches
in log), with a step of :data:`STEP` (5 % of the range: latencies act in whole control
sub-steps of 4-5 ms, so a much smaller step would see a staircase). The stencil (the centre,
``+-h`` along each parameter and the four corners of each pair: ``1 + 2k + 2k(k-1)``
replays) is moved inside the range for a parameter near its bound, and each window's
gradient carried back to the parameter by its own Hessian. ``sigma`` is ``nan`` for a
parameter along which the cost does not curve upward (``H_ii <= 0``: the log does not pin
it) and for one at an end of its fit range (``Candidate.at_bound``: the bound, not the cost,
made that minimum, and the report warns of it; DS3's pose-only rolling resistance at 0.1
turned ``H`` indefinite and took every other sigma with it), and the others' sandwich is
that with it held; all are ``nan`` when the rest of ``H`` is not positive definite either. It says nothing about a bias of the catalogue effect standing in for
something else (docs/gap.md, "Known limits").
"""
from __future__ import annotations

import itertools
import math
from concurrent.futures import ProcessPoolExecutor
from typing import Sequence

import numpy as np

from simrunner.workflows.gap.chain import _bounds01, with_parameters
from simrunner.workflows.gap.fit import CANDIDATES, Problem, _quiet_worker, window_values, window_values_task
from vehicle.description import CarDescription

STEP = 0.05  # the difference step, as a fraction of each parameter's fit range


def _dvalue_du(names: Sequence[str], u: np.ndarray) -> np.ndarray:
    """d value / d u of each parameter at ``u``, in the fit's ``[0, 1]`` coordinates
    (``chain._bounds01``: linear in the value, or in its log where the fit searches in log)."""
    out = []
    for c, x in zip((CANDIDATES[n] for n in names), u):
        lo, hi = c.to_x(c.lo), c.to_x(c.hi)
        out.append((hi - lo) * (c.from_x(lo + x * (hi - lo)) if c.log_scale else 1.0))  # d exp(x)/dx = exp(x)
    return np.array(out)


def parameter_sigma(problem: Problem, base: CarDescription, names: Sequence[str], values: dict[str, float],
                    *, jobs: int = 1, step: float = STEP) -> dict[str, float]:
    """The standard error of each parameter of ``values`` (the ``Effects`` fields of the
    effects ``names``, fitted on ``problem``'s windows with ``base`` as the car): the module
    docstring's sandwich; ``{}`` for no parameter."""
    names = list(names)
    k = len(names)
    if not k:
        return {}
    to_u, from_u = _bounds01(names)
    u = to_u(values)
    c = np.clip(u, step, 1.0 - step)  # the stencil's centre, inside the range
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
    cars = [with_parameters(base, {**values, **from_u(p)}) for p in points]
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs, initializer=_quiet_worker) as pool:
            f = np.array(list(pool.map(window_values_task, [(problem, car) for car in cars])))
    else:
        f = np.array([window_values(problem, car) for car in cars])
    n = f.shape[1]
    if n < 2 or not np.isfinite(f).all():
        return {CANDIDATES[m].field: math.nan for m in names}
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
    grad += hess @ (u - c)  # each window's gradient carried from the centre to the parameters
    out = {CANDIDATES[m].field: math.nan for m in names}
    h_all = hess.sum(axis=0)
    # the others: the cost does not curve along them, or the fit stopped at a bound (a minimum
    # the bound makes, not the cost's curvature)
    pinned = [i for i in range(k) if h_all[i, i] > 0.0
              and not CANDIDATES[names[i]].at_bound(values[CANDIDATES[names[i]].field])]
    h = h_all[np.ix_(pinned, pinned)]
    try:
        np.linalg.cholesky(h)
    except np.linalg.LinAlgError:
        return out
    g = grad[:, pinned]
    centred = g - g.mean(axis=0)
    b = centred.T @ centred * n / (n - 1)
    h_inv = np.linalg.inv(h)
    newton = np.clip(u[pinned] - h_inv @ g.sum(axis=0), 0.0, 1.0) - u[pinned]  # to the minimum within the range
    cov_u = h_inv @ b @ h_inv + np.outer(newton, newton)
    sigma = np.sqrt(np.maximum(np.diag(cov_u), 0.0)) * np.abs(_dvalue_du(names, u)[pinned])
    out.update({CANDIDATES[names[i]].field: float(s) for i, s in zip(pinned, sigma)})
    return out


__all__ = ["parameter_sigma", "window_values", "STEP"]
