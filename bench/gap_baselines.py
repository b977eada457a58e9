"""Two baselines for the gap chain (issue 10), run by ``bench.bench_gap --mode compare``.

Both see exactly what the chain saw: the logs as :func:`simrunner.workflows.gap.report.run_gap`
prepared them (glitches out, smoothed states, the same fit and held-out windows, the same
signals and normalisation, read back from the :class:`GapResult`).

(a) :func:`joint_least_squares`: one bounded least-squares fit of every catalogue
    parameter at once (``scipy.optimize.least_squares``, trf, forward-difference Jacobian
    with a step of :data:`LSQ_DIFF_STEP` of each parameter's fit range) on the normalised residuals of the
    chain's screening windows (:func:`simrunner.workflows.gap.screening.screening_problem`: the
    windows its joint refits use), in the chain's [0, 1]-scaled coordinates (log scale for
    the parameters whose neutral value is infinite), from the neutral car (infinite
    neutrals start at their upper bound). At most :data:`LSQ_MAX_NFEV` iterations. "Named":
    every parameter that moved more than :data:`MOVED_FRACTION` of its fit range from neutral.

(b) :func:`esindy`: E-SINDy (pysindy's ``EnsembleOptimizer`` around ``STLSQ``, bagging) of
    the longitudinal and yaw dynamics on the fit windows, with small libraries of the terms
    that catalogue effects produce (:data:`LONG_TERMS`, :data:`YAW_TERMS`): a least-squares
    model of the nominal car's replay of the same windows is the reference, and E-SINDy
    fits what that reference misses at the measured states (measured acceleration and yaw
    rate minus the reference's); catalogue parameters come from the reference coefficients
    plus the sparse differences (:func:`_map_effects`). Effects
    it can express: speed_scale, motor_lag (the first-order time constant of the speed
    response), rolling_resistance and drag (coasting decelerations), steering_gain,
    steering_offset, steering_asymmetry and tire_slip. "Named": an expressible effect whose
    parameter moved more than :data:`MOVED_FRACTION` of its fit range and whose 5-95 %
    bootstrap interval (over the ensemble's models) excludes neutral. Its held-out figures
    come from replaying the car with the named effects (the simulator calibrated by E-SINDy).

pysindy is optional: :func:`esindy` raises :class:`BaselineUnavailable` without it.
"""
from __future__ import annotations

import dataclasses
import importlib.util
import math
import time
import warnings
from dataclasses import dataclass

import numpy as np

MOVED_FRACTION = 0.03    # of a parameter's fit range (in the scaled coordinates): "moved from neutral"
LSQ_DIFF_STEP = 0.02     # finite-difference step, fraction of each parameter's fit range
LSQ_DEAD_ZONE = 0.01     # scaled coordinates this close to neutral are exactly neutral
LSQ_MAX_NFEV = 8         # least-squares iterations (each costs 1 + n_parameters replays)
SINDY_MODELS = 40        # bagged models of the ensemble
SINDY_THRESHOLD = 0.05   # STLSQ threshold on column-normalised terms, target scaled to unit RMS
RIDGE_ALPHA = 1e-3       # of the reference model (normalised columns), per sample
MIN_SPEED_MPS = 0.3      # samples slower than this are left out of the regressions
GRAVITY_MPS2 = 9.81

LONG_TERMS = ("drive*u", "drive*v", "drive", "coast*sign(v)", "coast*v|v|")
YAW_TERMS = ("v*delta", "v", "v*|delta|", "v^3*delta")


class BaselineUnavailable(RuntimeError):
    """An optional dependency of a baseline is missing (the message says which)."""


@dataclass(frozen=True)
class BaselineFit:
    """What a baseline found: every fitted parameter (Effects field -> value), the effects
    it names, and what it cost."""

    method: str
    parameters: dict[str, float]
    named: tuple[str, ...]
    evaluations: int
    wall_s: float
    detail: dict = dataclasses.field(default_factory=dict)


def problems(result, car):
    """``(fit_problem, held_problem)`` rebuilt from a GapResult (nominal ``car``, same
    windows, signals and scales). The fit problem is plain least squares (the baselines
    fit residual vectors); the held-out one is ``run_gap``'s own (its physics step and
    robust loss), so that held-out gaps compare with the chain's."""
    from simrunner.workflows.gap.fit import Problem, Segment

    parts = result.parts
    scales = result.settings["scales"]
    signals = tuple(result.settings["signals"])
    dt_s = result.settings["dt_s"]
    fit = Problem(car, tuple(Segment(p.log, p.derived, p.fit_windows) for p in parts if p.fit_windows),
                  scales, signals, dt_s)
    held = Problem(car, tuple(Segment(p.log, p.derived, p.held_windows) for p in parts if p.held_windows),
                   scales, signals, result.settings["held_dt_s"], robust_scale=result.settings["robust_scale"])
    return fit, held


def residual_vector(problem, car) -> np.ndarray:
    """The normalised residuals whose sum of squares is ``fit.cost_of(problem, car)``."""
    from simrunner.workflows.gap.fit import segment_residuals
    from simrunner.workflows.gap.replay import window_mask

    out = []
    for seg, res in zip(problem.segments, segment_residuals(problem, car)):
        m = window_mask(len(seg.log), seg.windows)
        for s in problem.signals:
            v = res[s][m] / problem.scales[s]
            out.append(np.where(np.isfinite(v), v, 1e3))
    return np.concatenate(out)


def _neutral_values(names) -> dict[str, float]:
    from simrunner.car.effects import EFFECTS

    return {EFFECTS[n].param: EFFECTS[n].neutral[0] for n in names}


def moved(names, values: dict[str, float], fraction: float = MOVED_FRACTION) -> list[str]:
    """The effects among ``names`` whose parameter in ``values`` is more than ``fraction`` of
    its fit range (scaled coordinates) away from neutral (an infinite neutral counts as the
    upper bound)."""
    from simrunner.workflows.gap.chain import _bounds01
    from simrunner.workflows.gap.fit import CANDIDATES

    out = []
    neutral = _neutral_values(names)
    for n in names:
        f = CANDIDATES[n].field
        if f not in values:
            continue
        to_u, _ = _bounds01([n])
        if abs(float(to_u({f: values[f]})[0] - to_u({f: neutral[f]})[0])) > fraction:
            out.append(n)
    return out


def joint_least_squares(fit_problem, names=None, *, max_nfev: int = LSQ_MAX_NFEV,
                        diff_step: float = LSQ_DIFF_STEP) -> BaselineFit:
    """Baseline (a) of the module docstring on ``fit_problem`` (its car is the start).

    The Jacobian is a forward difference with an absolute step ``h = diff_step`` in the
    scaled coordinates (inwards at the upper bound): scipy's own 2-point step is relative
    to ``|x|`` and would be ~1e-12 for every parameter whose neutral value is its lower
    bound (lags, latency, forces). For a parameter at its neutral value the column is the
    slope between ``h`` and ``2 h`` instead: switching a filtered effect on (the control
    sub-step of ``simrunner.car.effects``) is itself a small jump that a difference from
    neutral would read as a large slope. A coordinate within :data:`LSQ_DEAD_ZONE` of its
    neutral value maps to exactly neutral (an infinite neutral included): the start is the
    nominal car (not effects switched on at 1e-10: trf moves the start strictly inside the
    bounds), and a step that barely moves a parameter off neutral does not switch its
    effect on - otherwise every trial step switches on the deadband, the backlash, the ESC
    logic and the sub-step filters at once, and trf rejects every step."""
    from scipy.optimize import least_squares

    from simrunner.workflows.gap.chain import _bounds01, with_parameters
    from simrunner.workflows.gap.screening import screening_problem
    from simrunner.workflows.gap.fit import CANDIDATES

    t0 = time.perf_counter()
    names = list(CANDIDATES) if names is None else list(names)
    problem = screening_problem(fit_problem)
    base = problem.car
    fields = [CANDIDATES[n].field for n in names]
    to_u, from_u = _bounds01(names)
    neutral = _neutral_values(names)
    u_neutral = to_u({f: (CANDIDATES[n].hi if math.isinf(neutral[f]) else neutral[f]) for n, f in zip(names, fields)})
    u0 = to_u({f: float(getattr(base.effects, f)) for f in fields})
    cache: dict[bytes, np.ndarray] = {}

    def values_of(u: np.ndarray) -> dict[str, float]:
        values = from_u(u)
        for i, f in enumerate(fields):
            if abs(u[i] - u_neutral[i]) < LSQ_DEAD_ZONE:
                values[f] = neutral[f]
        return values

    def fun(u: np.ndarray) -> np.ndarray:
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        key = u.tobytes()
        if key not in cache:
            cache[key] = residual_vector(problem, with_parameters(base, values_of(u)))
        return cache[key]

    def jac(u: np.ndarray) -> np.ndarray:
        f0 = fun(u)
        out = np.empty((f0.size, u.size))
        for i in range(u.size):
            h = diff_step if u[i] + diff_step <= 1.0 else -diff_step
            e = u.copy()
            e[i] += h
            if abs(u[i] - u_neutral[i]) < LSQ_DEAD_ZONE:  # switched off: the slope just after switching on
                e2 = e.copy()
                e2[i] += h
                out[:, i] = (fun(e2) - fun(e)) / h
            else:
                out[:, i] = (fun(e) - f0) / h
        return out

    start_cost = float(np.dot(fun(u0), fun(u0)))
    sol = least_squares(fun, u0, jac=jac, bounds=(0.0, 1.0), method="trf", x_scale=1.0, max_nfev=max_nfev)
    u_best = min(cache, key=lambda k: float(np.dot(cache[k], cache[k])))  # the best point evaluated
    u_best = np.frombuffer(u_best, dtype=float)
    values = values_of(u_best)
    return BaselineFit("joint_lsq", values, tuple(moved(names, values)), len(cache), time.perf_counter() - t0,
                       {"cost": float(np.dot(cache[u_best.tobytes()], cache[u_best.tobytes()])),
                        "start_cost": start_cost, "status": int(sol.status), "iterations": int(sol.nfev)})


# --- (b) E-SINDy ---------------------------------------------------------------------------

def _window_smooth(t: np.ndarray, v: np.ndarray, windows) -> tuple[np.ndarray, np.ndarray]:
    """Savitzky-Golay value and derivative of ``v`` inside each window (the smoothing of
    ``logs.derive``: ``settings.smooth_s``, order 2, on a uniform grid), NaN elsewhere."""
    from scipy.signal import savgol_filter

    from simrunner.workflows.gap.settings import SETTINGS

    val, der = np.full(len(t), np.nan), np.full(len(t), np.nan)
    for w in windows:
        tt, vv = t[w.start:w.stop], v[w.start:w.stop]
        ok = np.isfinite(vv)
        if ok.sum() < 7:
            continue
        grid = np.linspace(tt[0], tt[-1], len(tt))
        step = grid[1] - grid[0]
        win = max(5, int(round(SETTINGS.smooth_s / step)) | 1)
        win = min(win, len(tt) if len(tt) % 2 else len(tt) - 1)
        g = np.interp(grid, tt[ok], vv[ok])
        val[w.start:w.stop] = np.interp(tt, grid, savgol_filter(g, win, 2, mode="interp"))
        der[w.start:w.stop] = np.interp(tt, grid, savgol_filter(g, win, 2, deriv=1, delta=step, mode="interp"))
    return val, der


def _features(v, u, delta, coast):
    drive = 1.0 - coast
    long = np.column_stack([drive * u, drive * v, drive, coast * np.sign(v), coast * v * np.abs(v)])
    yaw = np.column_stack([v * delta, v, v * np.abs(delta), v ** 3 * delta])
    return long, yaw


def _ridge(theta: np.ndarray, y: np.ndarray, alpha: float = RIDGE_ALPHA) -> np.ndarray:
    """Ridge regression on RMS-normalised columns (``alpha`` x samples): the reference's
    coast terms are nearly collinear (the plan coasts at two speeds), and plain least
    squares gives them large opposite coefficients that extrapolate badly."""
    col = np.sqrt(np.mean(theta ** 2, axis=0))
    col = np.where(col > 0, col, 1.0)
    x = theta / col
    beta = np.linalg.solve(x.T @ x + alpha * len(y) * np.eye(x.shape[1]), x.T @ y)
    return beta / col


def _ensemble(theta: np.ndarray, y: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """E-SINDy on one target: (median coefficients, every bagged model's coefficients)."""
    import pysindy as ps

    col = np.sqrt(np.mean(theta ** 2, axis=0))
    col = np.where(col > 0, col, 1.0)
    ys = float(np.sqrt(np.mean(y ** 2))) or 1.0
    np.random.seed(seed)  # pysindy's bagging draws from numpy's global generator
    opt = ps.EnsembleOptimizer(ps.STLSQ(threshold=SINDY_THRESHOLD), bagging=True, n_models=SINDY_MODELS)
    with warnings.catch_warnings():  # "eliminated all coefficients" is an answer here, not a problem
        warnings.simplefilter("ignore")
        opt.fit(theta / col, (y / ys)[:, None])
    models = np.array(opt.coef_list)[:, 0, :] * ys / col
    return np.median(models, axis=0), models


def _nonzero(k):
    k = np.asarray(k, dtype=float)
    return np.where(np.abs(k) > 1e-6, k, 1e-6)


def _map_effects(long, yaw, long_ref, yaw_ref, wheelbase_m: float, mass_kg: float) -> dict[str, np.ndarray]:
    """Catalogue parameters from coefficient arrays (last axis: the library terms; leading
    axes broadcast, so the ensemble's models map one by one)."""
    kv, kr = _nonzero(-long[..., 1]), _nonzero(-long_ref[..., 1])  # 1 / time constant of the speed response
    out = {
        "speed_scale": (long[..., 0] / kv) / (long_ref[..., 0] / kr),  # steady state v = (k_u / k_v) u
        "motor_lag_s": 1.0 / kv - 1.0 / kr,
        "rolling_resistance_coeff": -(long[..., 3] - long_ref[..., 3]) / GRAVITY_MPS2,
        "drag_coeff_kgpm": -(long[..., 4] - long_ref[..., 4]) * mass_kg,
        "steering_gain": yaw[..., 0] / yaw_ref[..., 0],
        "steering_offset_rad": (yaw[..., 1] - yaw_ref[..., 1]) / yaw_ref[..., 0],
        "steering_asymmetry": yaw[..., 2] / yaw[..., 0] - yaw_ref[..., 2] / yaw_ref[..., 0],
        "tire_slip_understeer_radps2pm": -wheelbase_m * (yaw[..., 3] - yaw_ref[..., 3]) / yaw_ref[..., 0],
    }
    return out


SINDY_EFFECTS = {"speed_scale": "speed_scale", "motor_lag": "motor_lag_s",
                 "rolling_resistance": "rolling_resistance_coeff", "drag": "drag_coeff_kgpm",
                 "steering_gain": "steering_gain", "steering_offset": "steering_offset_rad",
                 "steering_asymmetry": "steering_asymmetry", "tire_slip": "tire_slip_understeer_radps2pm"}


def esindy(result, car, *, seed: int = 0) -> BaselineFit:
    """Baseline (b) of the module docstring on the logs of ``result`` (nominal ``car``).

    1. Reference: the nominal car replayed in the fit windows; ordinary least squares of its
       acceleration and yaw rate on the full libraries gives the nominal model ``f_ref``
       (its coast terms may be ill-determined - only its predictions and its drive and
       ``v*delta`` coefficients are used).
    2. E-SINDy on what the nominal model misses at the measured states: ``a - f_ref`` and
       ``r - g_ref`` on the same libraries (sparse: unexcited terms drop out).
    3. Measured coefficients = reference + sparse difference, mapped to catalogue
       parameters (:func:`_map_effects`), per bagged model for the bootstrap interval."""
    if importlib.util.find_spec("pysindy") is None:
        raise BaselineUnavailable("E-SINDy baseline skipped: pysindy is not installed "
                                  "(pip install 'pysindy>=2.0')")
    from simrunner.workflows.gap.fit import CANDIDATES
    from simrunner.workflows.gap.replay import replay

    t0 = time.perf_counter()
    keys = ("long", "yaw", "a", "r")
    meas, ref = {k: [] for k in keys}, {k: [] for k in keys}
    limit = car.steering.limit_rad
    for p in result.parts:
        log, d = p.log, p.derived
        pred = replay(car, log, d, p.fit_windows, dt_s=result.settings["dt_s"])
        coast = log.coasting().astype(float)
        delta = np.clip(log.steer_cmd_rad, -limit, limit)
        v_ref, a_ref = _window_smooth(log.t_s, pred.speed_mps, p.fit_windows)
        r_ref, _ = _window_smooth(log.t_s, pred.yaw_rate_radps, p.fit_windows)
        for rows, v, a, r in ((meas, d.speed_mps, d.accel_mps2, d.yaw_rate_radps), (ref, v_ref, a_ref, r_ref)):
            ok = (np.isfinite(v_ref) & np.isfinite(v) & np.isfinite(a) & np.isfinite(r)
                  & (np.abs(v) >= MIN_SPEED_MPS))
            lf, yf = _features(v[ok], log.speed_cmd_mps[ok], delta[ok], coast[ok])
            for k, x in zip(keys, (lf, yf, a[ok], r[ok])):
                rows[k].append(x)
    m = {k: np.concatenate(v) for k, v in meas.items()}
    rf = {k: np.concatenate(v) for k, v in ref.items()}
    lr, yr = _ridge(rf["long"], rf["a"]), _ridge(rf["yaw"], rf["r"])
    dl, dl_all = _ensemble(m["long"], m["a"] - m["long"] @ lr, seed)
    dy, dy_all = _ensemble(m["yaw"], m["r"] - m["yaw"] @ yr, seed + 1)
    wb, mass = car.chassis.wheelbase_m, car.chassis.mass_kg
    point = {f: float(v) for f, v in _map_effects(lr + dl, yr + dy, lr, yr, wb, mass).items()}
    spread = _map_effects(lr + dl_all, yr + dy_all, lr, yr, wb, mass)
    named, params = [], {}
    for eff, f in SINDY_EFFECTS.items():
        c = CANDIDATES[eff]
        if not math.isfinite(point[f]):
            continue
        params[f] = float(min(max(point[f], c.lo), c.hi))
        lo, hi = np.nanpercentile(spread[f], [5, 95])
        neutral = _neutral_values([eff])[f]
        if moved([eff], {f: params[f]}) and not (lo <= neutral <= hi):
            named.append(eff)
    return BaselineFit("esindy", params, tuple(named), 2, time.perf_counter() - t0,
                       {"long_delta": dict(zip(LONG_TERMS, dl.tolist())), "yaw_delta": dict(zip(YAW_TERMS, dy.tolist())),
                        "long_ref": dict(zip(LONG_TERMS, lr.tolist())), "yaw_ref": dict(zip(YAW_TERMS, yr.tolist())),
                        "samples": int(len(m["a"]))})


__all__ = ["BaselineFit", "BaselineUnavailable", "joint_least_squares", "esindy", "problems",
           "residual_vector", "moved", "MOVED_FRACTION", "SINDY_EFFECTS"]
