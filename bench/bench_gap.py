"""Bench of the gap workflow (issue 10's targets) on synthetic and real logs.

Modes (``--mode``, comma-separated; default: all of them, small):

``single``
    One hidden effect per log (as before issue 10): every :data:`NONE_EVERY`-th trial is
    effect-free, the others cycle through the catalogue (:func:`trial_effect`); each trial's
    plan seed, magnitude, nuisance (mass and grip +-3 %) and noise come from
    ``numpy.random.default_rng([SEED, k])``. Pose + speed sensors.
``multi``
    2 or 3 simultaneous effects (even trials 2, odd 3), one from each of as many different
    :data:`GROUPS` (:func:`multi_effects`; the rule: never two effects of one group, the
    groups gather effects that act on the same thing in nearly the same way, e.g. at most
    one of steering_gain / steering_asymmetry / steer_limit_scale), magnitudes from
    ``synth.RANGES``, with the same nuisance and noise.
``speed_gyro``
    Logs with a speed sensor and a gyro only (no pose): trials cycle none / one effect /
    two effects / one effect, over the effects such a log can reveal
    (``report.cannot_reveal`` with the signals speed and yaw rate).
``tenth``
    Another car at another rate: one hidden effect per log as in ``single`` (every
    :data:`NONE_EVERY`-th log effect-free), on a 1:10 car (:func:`tenth_car`: 3.5 kg,
    wheelbase 0.33 m, 8 m/s, drive and brake limits of 6 and 8 m/s^2, near the tyres' grip,
    servo 3.5 rad/s) driving its own plan (``make_plan(car)``: 181 s) with a controller that
    runs at irregular stamps, about 30 Hz (:class:`SlowController`: it acts at each 50-Hz plan
    row with probability :data:`TENTH_KEEP` and holds its command in between), its pose and
    speed logged when it acts. The catalogue includes ``front_drive`` (the file says rear drive)
    and ``inertia``, which the default car's logs cannot show (:data:`GRIP_LIMITED`).
``merged``
    The ``tenth`` logs' effects and seeds, with the controller at every 50-Hz plan row and a
    log written as a merged topic log would be: the pose and speed at about 30 Hz (each row
    kept with probability :data:`TENTH_KEEP`), the commands at their own stamps
    (``RunLog.command_steps``). The chain runs on it, and again on the same rows alone
    (``rows_held``: each row's command held to the next, the command changes between rows
    lost), so the two columns show what the commands' stamps give.
``unmodelled``
    Logs no catalogue effect explains (the issue's "is told so"): the default car, pose +
    speed, no catalogue effect, and one thing the catalogue lacks - even trials wheels that
    turn :data:`REVERSE_PULL_RAD` to one side while reversing only (slack in the linkage
    taken up the other way round when the wheels are pushed; :class:`ReversePull`), odd
    trials a floor tilted by :data:`SLOPE_DEG` in a random direction (``CarSim(slope_rad=)``).
    Figures: logs where nothing is named; logs whose report lists an ``unexplained`` leftover;
    for the pull, logs whose leftovers name a steering signal (yaw rate, yaw, position) while
    reversing.
``compare``
    The ``multi`` logs (the same seeds: a run of ``multi,compare`` runs the chain once per
    log) with two baselines on the same prepared logs, windows and residuals
    (:mod:`bench.gap_baselines`): (a) one joint least-squares fit of every catalogue
    parameter, (b) E-SINDy of the longitudinal and yaw dynamics.
``glitch``
    The ``multi`` logs (same seeds) run twice: as made, and with one glitch put in at a
    random sample of the middle 80 % (:func:`inject_glitch`; kind ``k % 5``: the position
    displaced by 0.5-1 m for 3 samples, the heading by 0.3-3 rad for 2-20 samples, the pose
    frozen for 1-3 s while the car drives on, 0.5-2 s of rows dropped, or the speed off by
    1-2 m/s for 1-3 readings; before 2026-11-29 ``k % 4`` without the speed spike). Figures: the
    glitch listed; the names unchanged by it (issue 10: glitches "never drive the naming");
    of the logs whose names changed, those where every changed name stands in a
    "cannot tell them apart" pair of either run (``Step.alike``).
``real``
    The two shared real logs (``REAL_DIR``, or the folder ``NXPCUP_REAL_LOGS`` names, as in
    the tests; skipped when absent) with their car, one at a time.
``real_partial``
    The same two real runs as a team with partial sensors would log them: a wheel encoder
    and a gyro (no pose), and a pose only (an overhead camera; no speed sensor, no gyro).
    Made from the data sets' raw topic files (``REAL_DIR/raw``) by
    :func:`bench.real_topics.partial_log_csv` into a temporary CSV with the topics' own
    column names, read through a column mapping (split stamps, deg/s, a quaternion).
``timing``
    One 60-s synthetic log with two hidden effects through the whole chain, ``run_gap(jobs=2)``.

Signal-to-noise ratio of a hidden effect: replay the noise-free log (same seed) in its
windows from the exact states with the nuisance car plus only that effect and with the
nuisance car alone; RMS over the windows of the difference in each signal the log has (x,
y, yaw, speed; or speed and yaw rate), over that signal's noise sigma, quadratic mean over
the signals. Parameter error: ``|fit - true| / |true - neutral|`` (``/ |true|`` when the
neutral value is infinite), over correctly named effects. Held-out figures: the run's own
``gap_after / gap_before`` and position RMSE after/before on the held-out windows (against
the noisy measured log), and the same for the baselines' cars on the same windows.

``python -m bench.bench_gap [--mode single,multi,...] [--trials N] [--first K | --only K,K,...] [--jobs J] [--screen S] [--out FILE.json]``
(``--results``: after the run, its targets into ``bench/results/gap.json``, which
``python tools/render_bench_tables.py`` renders into docs/gap.md)
(``--screen``: ``run_gap``'s ``screen_max_s``, e.g. 0 to screen and refit on all fit windows)
(``--table FILE.json ...`` prints the tables of saved rows again, pooling several files: a
large sample can be built in runs of trials ``K .. K+N-1`` each, as the trial designs
depend on the trial number only). Synthetic trials run in
``--jobs`` processes, one ``run_gap(jobs=1)`` each; real and timing runs use ``--jobs``
processes inside ``run_gap``. ``python -m bench`` runs ``main()``: every mode, small
(:data:`SMALL_TRIALS` per synthetic mode; about 130 minutes on 2 cores with the shared real logs,
``glitch`` about 37 of them).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Iterator

import numpy as np

from bench.gap_scoring import (GLITCH_KINDS, SYNTH_TARGETS, figures, fmt_figure, inject_glitch, method_row,
                               replay_snr, sigma_text, target_rows)

SEED = 20240
NONE_EVERY = 4
SMALL_TRIALS = 6
MODES = ("single", "multi", "speed_gyro", "tenth", "merged", "unmodelled", "compare", "glitch", "real", "real_partial",
         "timing")
_MODE_TAG = {"multi": 2, "compare": 2, "speed_gyro": 3, "tenth": 4, "merged": 4, "unmodelled": 5,
             "glitch": 7}  # seed tags: compare uses the multi logs; glitch the multi logs, its own for the glitch
# effects that show only where the drive and brake limits reach the tyres' grip (or the tyres
# slide): not on the default car (3.1 m/s^2), so the default-car modes leave them out; ``tenth`` has them
GRIP_LIMITED = ("front_drive", "inertia")
TENTH_KEEP = 0.6  # share of the 50-Hz plan rows the ``tenth`` controller acts at (irregular stamps, ~30 Hz)
REVERSE_PULL_RAD = (0.03, 0.08)  # ``unmodelled``: steering offset while reversing, uniform (sign random)
SLOPE_DEG = (1.5, 3.0)  # ``unmodelled``: floor tilt, uniform in this range
REAL_DIR = Path(os.environ.get("NXPCUP_REAL_LOGS",
                               Path(__file__).resolve().parents[2] / "shared" / "data" / "real_logs"))
REAL_LOGS = ("f1tenth_DS2.csv", "f1tenth_DS3.csv")
REAL_CAR = "f1tenth_car.toml"
TIMING_LOG_S = 60.0
TIMING_EFFECTS = {"steering_offset": 0.02, "motor_lag": 0.15}

# Effects that act on the same thing in nearly the same way: a multi-effect log never hides
# two of one group (every catalogue effect is in exactly one group).
GROUPS: dict[str, tuple[str, ...]] = {
    "steering trim": ("steering_offset",),
    "steering scale": ("steering_gain", "steering_asymmetry", "steer_limit_scale"),
    "steering dynamics": ("steering_lag", "steering_rate_limit", "servo_rate_scale", "steering_play"),
    "lateral grip": ("friction", "tire_slip"),
    "delay": ("command_latency",),
    "speed level": ("speed_scale", "top_speed", "throttle_deadband"),
    "speed response": ("motor_lag", "accel_scale", "brake_scale", "mass_scale", "lift_lag"),
    "coasting losses": ("rolling_resistance", "drag"),
    "reverse": ("esc_brake_reverse",),
}


# --- trial design ------------------------------------------------------------------------------

def trial_effect(k: int, effects: list[str]) -> str | None:
    """The hidden effect of single-mode trial ``k``: every :data:`NONE_EVERY`-th trial is
    effect-free, the others cycle through ``effects``."""
    if k % NONE_EVERY == 0:
        return None
    return effects[(k - 1 - k // NONE_EVERY) % len(effects)]


def multi_effects(n: int, rng: np.random.Generator, allowed: list[str] | None = None) -> list[str]:
    """``n`` effects from ``n`` different :data:`GROUPS` (groups and members drawn from
    ``rng``; only ``allowed`` effects when given)."""
    groups = {g: [e for e in members if allowed is None or e in allowed] for g, members in GROUPS.items()}
    names = [g for g, members in groups.items() if members]
    picked = rng.choice(len(names), size=n, replace=False)
    return [str(rng.choice(groups[names[i]])) for i in sorted(picked)]


def tenth_car():
    """The ``tenth`` mode's car: generic 1:10 numbers (not any one real car's), a rear-drive
    file whose drive and brake limits reach the grip of its rear tyres alone."""
    from vehicle.description import CarDescription, Chassis, Drive, Steering, Wheels

    return CarDescription(
        name="tenth_scale",
        chassis=Chassis(mass_kg=3.5, wheelbase_m=0.33, track_m=0.28, length_m=0.5, width_m=0.29, height_m=0.1,
                        rear_overhang_m=0.09, cog_height_m=0.07),
        wheels=Wheels(radius_m=0.05, width_m=0.045, mass_kg=0.1, friction_mu=1.0),
        steering=Steering(limit_rad=0.42, rate_radps=3.5),
        drive=Drive(max_speed_mps=8.0, max_accel_mps2=6.0, max_brake_mps2=8.0))


def mode_car(mode: str):
    """The car of ``mode``'s synthetic logs and of their gap runs (None: the default car)."""
    return tenth_car() if mode in ("tenth", "merged") else None


class SlowController:
    """A controller at irregular stamps: of the plan's rows (one ``set_command`` each, in
    ``run_plan``) it acts at the first and then at each with probability ``keep``, and holds
    its command (and coasting) in between; ``acted`` records the rows it acted at, the rows
    its log keeps, so the log holds every command the car got. Wraps a simulator."""

    def __init__(self, sim, rng: np.random.Generator, keep: float):
        self._sim, self._rng, self._keep = sim, rng, keep
        self.acted: list[bool] = []
        self._coast: bool | None = None

    def set_coast(self, coast: bool) -> None:
        self._coast = bool(coast)  # applied at the next row the controller acts at

    def set_command(self, speed_mps: float, steer_rad: float, yaw_rate_radps: float | None = None) -> None:
        act = not self.acted or bool(self._rng.random() < self._keep)
        self.acted.append(act)
        if act:
            if self._coast is not None:
                self._sim.set_coast(self._coast)
                self._coast = None
            self._sim.set_command(speed_mps, steer_rad, yaw_rate_radps)

    def __getattr__(self, name):
        return getattr(self._sim, name)


class ReversePull:
    """A car whose wheels turn ``offset_rad`` to one side while the speed command is negative
    only (the linkage's slack taken up the other way round when reversing pushes the wheels):
    not in the catalogue, whose offset acts in both directions. Wraps a simulator;
    everything else is the inner one's."""

    def __init__(self, sim, offset_rad: float):
        self._sim, self._offset = sim, offset_rad

    def set_command(self, speed_mps: float, steer_rad: float, yaw_rate_radps: float | None = None) -> None:
        self._sim.set_command(speed_mps, steer_rad + self._offset if speed_mps < 0.0 else steer_rad, yaw_rate_radps)

    def __getattr__(self, name):
        return getattr(self._sim, name)


def unmodelled_design(k: int) -> tuple[str, float, object]:
    """``(what, magnitude, sim_factory)`` of ``unmodelled`` trial ``k`` (see the module docstring)."""
    from pieces.pose import Pose2
    from simrunner.car.effects import make_sim

    rng = np.random.default_rng([SEED, _MODE_TAG["unmodelled"], k, 1])
    if k % 2 == 0:
        pull = float(rng.uniform(*REVERSE_PULL_RAD) * rng.choice([-1.0, 1.0]))
        return "reverse_pull_rad", pull, lambda car, dt_s, start: ReversePull(make_sim(car, dt_s=dt_s, start=start), pull)
    slope, heading = float(rng.uniform(*SLOPE_DEG)), float(rng.uniform(-math.pi, math.pi))

    def sloped(car, dt_s, start):  # the plan's frame turned by ``heading`` on a floor descending along +x
        return make_sim(car, dt_s=dt_s, start=Pose2(start.x_m, start.y_m, start.yaw_rad + heading),
                        slope_rad=math.radians(slope))
    return "floor_slope_deg", slope, sloped


def design(mode: str, k: int) -> tuple[list[str], str, np.random.Generator]:
    """``(hidden effects, sensors, rng for make_measured_log)`` of trial ``k`` of ``mode``;
    the same arguments always give the same log."""
    from simrunner.workflows.gap.workflow import cannot_reveal
    from simrunner.workflows.gap.synth import RANGES

    from simrunner.car.effects import EFFECTS

    default_car = [e for e in RANGES if e not in GRIP_LIMITED and EFFECTS[e].requires != "slip"]
    if mode == "single":
        e = trial_effect(k, default_car)
        return ([e] if e else []), "pose_speed", np.random.default_rng([SEED, k])
    grouped = [e for members in GROUPS.values() for e in members]
    if sorted(grouped) != sorted(default_car):
        raise ValueError(f"GROUPS must hold every synthetic effect of the default car once (got "
                         f"{sorted(grouped)}, expected {sorted(default_car)})")
    rng = np.random.default_rng([SEED, _MODE_TAG[mode], k])
    if mode in ("tenth", "merged"):  # the same effects and seeds
        e = trial_effect(k, [e for e in RANGES if EFFECTS[e].requires != "slip"])
        return ([e] if e else []), "pose_speed", rng
    if mode == "unmodelled":
        return [], "pose_speed", rng
    if mode in ("multi", "compare"):
        return multi_effects(2 + k % 2, rng), "pose_speed", rng
    if mode == "speed_gyro":
        hidden = cannot_reveal(default_car, ("speed_mps", "yaw_rate_radps"))
        allowed = [e for e in default_car if e not in hidden]
        kind = k % 4
        if kind == 0:
            return [], "speed_gyro", rng
        if kind == 2:
            return multi_effects(2, rng, allowed), "speed_gyro", rng
        return [allowed[(k // 2 * 7 + kind) % len(allowed)]], "speed_gyro", rng
    raise ValueError(f"mode {mode!r}: expected one of {', '.join(MODES)}")


# --- one synthetic trial -----------------------------------------------------------------------

def _sensor_signals(sensors: str):
    from simrunner.workflows.gap.synth import NOISE_GYRO_RADPS, NOISE_POS_M, NOISE_SPEED_MPS, NOISE_YAW_RAD, SENSORS

    sigma = {"x_m": NOISE_POS_M, "y_m": NOISE_POS_M, "yaw_rad": NOISE_YAW_RAD, "speed_mps": NOISE_SPEED_MPS,
             "yaw_rate_radps": NOISE_GYRO_RADPS}
    return {s: sigma[s] for s in SENSORS[sensors]}


def effect_snr(mode: str, k: int) -> dict[str, float]:
    """SNR of each hidden effect of trial ``k`` (module docstring)."""
    from simrunner.car.effects import neutral_car
    from simrunner.workflows.gap.synth import make_measured_log

    effects, sensors, rng = design(mode, k)
    if not effects:
        return {}
    exact, truth = make_measured_log(effects, rng=rng, noise=False, sensors=sensors, car=mode_car(mode))
    # the nuisance mass and grip, no effect
    return replay_snr(neutral_car(truth.car), exact, effects, truth.values, _sensor_signals(sensors))


def held_out(result, car_before, car_after) -> dict:
    """Held-out gap and RMSE of ``car_after`` vs ``car_before`` on ``result``'s held-out
    windows (the definitions of ``run_gap``: gap = mean squared normalised residual)."""
    from simrunner.workflows.gap.fit import cost_of
    from simrunner.workflows.gap.replay import REPORT_SIGNALS, replay, residuals, rmse, window_mask

    from bench.gap_baselines import problems

    _, held = problems(result, car_before)
    n = max(held.n_values, 1)
    gb, ga = cost_of(held, car_before) / n, cost_of(held, car_after) / n
    out = {"gap_before": gb, "gap_after": ga}
    for tag, car in (("before", car_before), ("after", car_after)):
        res, masks = [], []
        for p in result.parts:
            if p.held_windows:
                pred = replay(car, p.log, p.derived, p.held_windows, dt_s=result.settings["held_dt_s"])
                res.append(residuals(p.log, p.derived, pred))
                masks.append(window_mask(len(p.log), p.held_windows))
        sig = [s for s in REPORT_SIGNALS if all(s in r for r in res)]
        joined = {s: np.concatenate([r[s] for r in res]) for s in sig}
        out[f"rmse_{tag}"] = rmse(joined, np.concatenate(masks), sig)
    return out


def _screen(screen_max_s: float | None) -> dict:
    """``run_gap``'s keyword for ``--screen`` (none: the chain's default subset)."""
    return {} if screen_max_s is None else {"screen_max_s": screen_max_s}


def _glitch_trial(k: int, screen_max_s: float | None) -> dict:
    from simrunner.workflows.gap.fit import _quiet_worker
    from simrunner.workflows.gap.workflow import run_gap
    from simrunner.workflows.gap.synth import make_measured_log

    _quiet_worker()
    effects, sensors, rng = design("multi", k)
    log, truth = make_measured_log(effects or None, rng=rng, sensors=sensors)
    kind = GLITCH_KINDS[k % len(GLITCH_KINDS)]
    bad, t0, t1 = inject_glitch(log, kind, np.random.default_rng([SEED, _MODE_TAG["glitch"], k]))
    t_start = time.perf_counter()
    row = {"mode": "glitch", "trial": k, "screen_max_s": screen_max_s, "effects": effects, "values": truth.values,
           "glitch": {"kind": kind, "t_start_s": t0, "t_end_s": t1}}
    for tag, lg in (("clean", log), ("glitchy", bad)):
        r = run_gap(lg, jobs=1, **_screen(screen_max_s))
        row[tag] = {"named": list(r.effects), "parameters": r.parameters, "gap_before": r.gap_before,
                    "gap_after": r.gap_after,
                    "alike": _alike(r),
                    "glitches": [(g.kind.value, g.t_start_s, g.t_end_s, g.column) for _, g in r.glitches]}
    row["glitch"]["listed"] = [g for g in row["glitchy"]["glitches"] if g[2] >= t0 - 0.1 and g[1] <= t1 + 0.1]
    row["wall_s"] = time.perf_counter() - t_start
    return row


def _alike(result) -> list[tuple]:
    """``(step, kept, look-alike, z)`` of every look-alike a step recorded (``Step.alike``)."""
    return [(s.index, s.kept.effect, a.effect, a.z) for s in result.chain.steps if s.kept is not None for a in s.alike]


def _trial(mode: str, k: int, baselines: bool, screen_max_s: float | None = None) -> dict:
    if mode == "glitch":
        return _glitch_trial(k, screen_max_s)
    from simrunner.car.effects import neutral_car
    from simrunner.workflows.gap.fit import _quiet_worker
    from simrunner.workflows.gap.workflow import run_gap
    from simrunner.workflows.gap.synth import make_measured_log

    _quiet_worker()
    effects, sensors, rng = design(mode, k)
    car = mode_car(mode)
    unmodelled = unmodelled_design(k) if mode == "unmodelled" else None
    factory = unmodelled[2] if unmodelled else None
    slow: list[SlowController] = []
    if mode == "tenth":
        from simrunner.car.effects import make_sim

        def factory(car_, dt_s, start):
            slow.append(SlowController(make_sim(car_, dt_s=dt_s, start=start),
                                       np.random.default_rng([SEED, _MODE_TAG[mode], k, 1]), TENTH_KEEP))
            return slow[-1]
    log, truth = make_measured_log(effects or None, rng=rng, sensors=sensors, car=car, sim_factory=factory)
    if slow:
        if len(slow[0].acted) != len(log):  # pragma: no cover - run_plan open loop: one row per plan row
            raise ValueError("tenth: the log's rows are not the plan's")
        log = log.subset(np.flatnonzero(slow[0].acted))
    rows_only = None
    if mode == "merged":  # the pose and speed at ~30 Hz, every command at its own stamp
        from simrunner.telemetry.log import CommandSteps

        kept = np.random.default_rng([SEED, _MODE_TAG[mode], k, 1]).random(len(log)) < TENTH_KEEP
        kept[0] = True
        rows_only = log.subset(np.flatnonzero(kept))
        log = dataclasses.replace(rows_only, command_steps=CommandSteps(log.t_s, log.speed_cmd_mps, log.steer_cmd_rad,
                                                                        log.coast))
    t0 = time.perf_counter()
    result = run_gap(log, car, jobs=1, **_screen(screen_max_s))
    wall = time.perf_counter() - t0
    nominal = neutral_car(result.car)
    held = {"gap_before": result.gap_before, "gap_after": result.gap_after,
            "rmse_before": result.rmse_before, "rmse_after": result.rmse_after}
    row = {"mode": mode, "trial": k, "screen_max_s": screen_max_s, "sensors": sensors, "effects": effects, "values": truth.values,
           "nuisance": {"mass_factor": truth.mass_factor, "friction_factor": truth.friction_factor},
           "snr": effect_snr(mode, k), "signals": list(result.settings["signals"]),
           "unrevealable": sorted(result.unrevealable),
           "chain": method_row(result.effects, result.parameters, truth.values, effects, held, wall,
                                {"steps": [(s.index, s.kept.effect if s.kept else None, s.gap_before, s.gap_after)
                                           for s in result.chain.steps],
                                 # every refitted candidate (to study the tests' thresholds afterwards)
                                 "trials": [(s.index, t.effect, t.improvement, t.delta_bic,
                                             1.0 - t.held_gap / s.held_gap_before if s.held_gap_before > 0 else 0.0,
                                             t.kept, t.reason) for s in result.chain.steps for t in s.trials],
                                 "pruned": [(t.effect, after) for t, after in zip(result.chain.pruned,
                                                                                 result.chain.pruned_after)],
                                 "alike": _alike(result)},
                                result.parameter_sigma, result.parameter_spans),
           "leftovers": [{k_: d[k_] for k_ in ("signal", "regime", "times_noise", "regimes", "text")}
                         for d in result.leftovers]}
    if unmodelled:
        row["unmodelled"] = {"what": unmodelled[0], "value": unmodelled[1]}
    if rows_only is not None:
        t1 = time.perf_counter()
        alone = run_gap(rows_only, car, jobs=1, **_screen(screen_max_s))
        row["rows_held"] = method_row(alone.effects, alone.parameters, truth.values, effects,
                                       {"gap_before": alone.gap_before, "gap_after": alone.gap_after,
                                        "rmse_before": alone.rmse_before, "rmse_after": alone.rmse_after},
                                       time.perf_counter() - t1)
    if baselines:
        from bench.gap_baselines import BaselineUnavailable, esindy, joint_least_squares, problems
        from simrunner.workflows.gap.chain import with_parameters

        fit_problem, _ = problems(result, nominal)
        a = joint_least_squares(fit_problem)
        row["joint_lsq"] = method_row(a.named, a.parameters, truth.values, effects,
                                       held_out(result, nominal, with_parameters(nominal, a.parameters)),
                                       a.wall_s, {"evaluations": a.evaluations, **a.detail})
        try:
            b = esindy(result, nominal, seed=k)
        except BaselineUnavailable as exc:
            row["esindy"] = {"skipped": str(exc)}
        else:
            fields = _sindy_fields()
            named_params = {fields[e]: b.parameters[fields[e]] for e in b.named}
            row["esindy"] = method_row(b.named, b.parameters, truth.values, effects,
                                        held_out(result, nominal, with_parameters(nominal, named_params)),
                                        b.wall_s, {"detail": b.detail})
    row["wall_s"] = time.perf_counter() - t0
    return row


def _sindy_fields() -> dict[str, str]:
    from bench.gap_baselines import SINDY_EFFECTS

    return SINDY_EFFECTS


# --- real logs and timing ------------------------------------------------------------------------

def real_rows(jobs: int, real_dir: Path = REAL_DIR, screen_max_s: float | None = None) -> Iterator[dict]:
    """One row per shared real log, each as it is done (none when the folder is absent)."""
    from simrunner.telemetry.log import read_log
    from vehicle.description import load_car

    if not (real_dir / REAL_CAR).exists():
        return
    car = load_car(real_dir / REAL_CAR)
    for name in REAL_LOGS:
        if (real_dir / name).exists():
            yield _real_row("real", name, lambda path=real_dir / name: read_log(path), car, jobs, screen_max_s)


def _real_row(mode: str, name: str, load, car, jobs: int, screen_max_s: float | None = None) -> dict:
    """Run the workflow on the log ``load()`` gives; the row records a traceback as such."""
    from simrunner.workflows.gap.workflow import run_gap

    t0 = time.perf_counter()
    row = {"mode": mode, "log": name, "screen_max_s": screen_max_s}
    try:
        r = run_gap(load(), car, jobs=jobs, **_screen(screen_max_s))
    except Exception:  # noqa: BLE001 - the target is "no traceback": record it
        row["error"] = traceback.format_exc()
    else:
        row.update(effects=r.effects, parameters=r.parameters, parameter_sigma=r.parameter_sigma, gap_before=r.gap_before, gap_after=r.gap_after,
                   rmse_before=r.rmse_before, rmse_after=r.rmse_after, signals=list(r.settings["signals"]),
                   steps=[(s.index, s.kept.effect, s.gap_before, s.gap_after)  # the report's held-out gap
                          for s in r.chain.steps if s.kept is not None],
                   rejected=[(k, t.effect, t.reason) for k, t in r.chain.rejected],
                   pruned=[(t.effect, after) for t, after in zip(r.chain.pruned, r.chain.pruned_after)],
                   glitches=len(r.glitches), stop=r.chain.stop_reason)
    row["wall_s"] = time.perf_counter() - t0
    return row


def real_partial_rows(jobs: int, real_dir: Path = REAL_DIR, screen_max_s: float | None = None) -> Iterator[dict]:
    """One row per shared real data set and partial sensor set, each as it is done (none when
    absent)."""
    import tempfile

    from bench.real_topics import COLUMNS, SENSORS, partial_log_csv
    from simrunner.telemetry.columns import column_map_from
    from simrunner.telemetry.log import read_log
    from vehicle.description import load_car

    if not (real_dir / REAL_CAR).exists():
        return
    car = load_car(real_dir / REAL_CAR)
    with tempfile.TemporaryDirectory() as tmp:
        for name in REAL_LOGS:
            raw = real_dir / "raw" / name.removeprefix("f1tenth_").removesuffix(".csv")
            if not (raw / "commandData.csv").exists():
                continue
            for sensors in SENSORS:
                path = Path(tmp) / f"{raw.name}_{sensors}.csv"
                partial_log_csv(raw, path, sensors)
                columns = column_map_from(None, COLUMNS[sensors])
                yield _real_row("real_partial", f"{raw.name} {sensors.replace('_', '+')}",
                                lambda: read_log(path, columns=columns), car, jobs, screen_max_s)


def timing_row(jobs: int) -> dict:
    """The whole chain on a :data:`TIMING_LOG_S` synthetic log with two hidden effects."""
    from simrunner.workflows.gap.workflow import run_gap
    from simrunner.workflows.gap.synth import make_measured_log

    log, truth = make_measured_log(list(TIMING_EFFECTS), value=list(TIMING_EFFECTS.values()),
                                   rng=np.random.default_rng([SEED, 6]), duration_s=TIMING_LOG_S)
    t0 = time.perf_counter()
    r = run_gap(log, jobs=jobs)
    wall = time.perf_counter() - t0
    return {"mode": "timing", "log_s": log.duration_s, "jobs": jobs, "wall_s": wall, "hidden": truth.values,
            "effects": r.effects, "parameters": r.parameters, "parameter_sigma": r.parameter_sigma,
            "steps": len(r.chain.steps),
            "refits": sum(len(s.trials) for s in r.chain.steps), "swaps": [sw.into for sw in r.chain.swaps],
            "pruned": [t.effect for t in r.chain.pruned]}


# --- figures, targets, tables ----------------------------------------------------------------------


# Issue 10's targets on synthetic logs: (mode, figures() key, what, goal, at least (True) or
# at most, limit, percent). "multi" counts the rows of the multi and compare modes.


def _trial_table(rows: list[dict]) -> str:
    lines = [f"{'mode':<13}{'k':>3}  {'hidden (SNR)':<64}{'named by the chain':<44}{'p.err':>16}{'pos a/b':>8}"
             f"{'gap a/b':>8}{'wall':>6}"]
    for r in rows:
        hid = ", ".join(f"{e} ({r['snr'][e]:.1f})" for e in r["effects"]) or "none"
        if "unmodelled" in r:
            hid = f"{r['unmodelled']['what']} {r['unmodelled']['value']:.3g} (not in the catalogue)"
        c = r["chain"]
        errs = ", ".join(f"{p['rel_err']:.0%}" for p in c["per_effect"].values() if p["rel_err"] is not None)
        pb = c["rmse_before"].get("position_m")
        pos = f"{c['rmse_after']['position_m'] / pb:.2f}" if pb else "-"
        lines.append(f"{r['mode']:<13}{r['trial']:>3}  {hid:<64}{', '.join(c['named']) or 'none':<44}{errs:>16}"
                     f"{pos:>8}{c['gap_after'] / c['gap_before']:>8.2f}{c['wall_s']:>6.0f}")
    notes = [_nuisance_note(r) for r in rows]
    return "\n".join(lines + [n for n in notes if n])


# a spurious effect that acts like a nuisance factor of the log's car: the factor beside it
_NUISANCE_OF = {"friction": ("friction_scale", "friction_factor", "grip"), "mass_scale": ("mass_scale", "mass_factor", "mass")}


def _nuisance_note(row: dict) -> str:
    """A line for a spurious ``friction`` or ``mass_scale``: its fitted value beside the log's
    hidden grip or mass factor (the +-3 % nuisance, real but not counted as an effect)."""
    nuisance = row.get("nuisance")
    if not nuisance:  # rows saved before the nuisance was kept
        return ""
    parts = []
    for e in row["chain"]["spurious"]:
        field, key, what = _NUISANCE_OF.get(e, (None, None, None))
        if field in row["chain"]["parameters"]:
            parts.append(f"{field} {row['chain']['parameters'][field]:.4g} (the car's hidden {what} factor "
                         f"{nuisance[key]:.4g})")
    return f"  {row['mode']} {row['trial']}: spurious {'; '.join(parts)}" if parts else ""


def _rows_held_table(rows: list[dict]) -> str:
    """``merged`` mode: the chain on the commands' own stamps vs on the rows alone."""
    lines = ["", f"merged logs: commands at their own stamps vs held per row ({len(rows)} logs):",
             f"{'method':<26}{'named, SNR>=3':>15}{'false claims':>14}{'spurious':>14}{'med p.err':>16}"
             f"{'med gap a/b':>13}"]
    for method, label in (("chain", "commands at their stamps"), ("rows_held", "held per row")):
        f = figures(rows, method)
        lines.append(f"{label:<26}{fmt_figure(f['single_named_hi']):>15}{fmt_figure(f['false_claims']):>14}"
                     f"{fmt_figure(f['any_spurious']):>14}{fmt_figure(f['single_perr']):>16}{fmt_figure(f['gap_ratio'], False):>13}")
    for r in rows:
        named = {m: ", ".join(f"{n} {v:.4g}" for n, v in r[m]["parameters"].items()) or "none"
                 for m in ("chain", "rows_held")}
        truth = ", ".join(f"{n} {v:.4g}" for n, v in r["values"].items()) or "none"
        lines.append(f"  {r['trial']:>2} hidden {truth}: stamps {named['chain']}; rows {named['rows_held']}")
    return "\n".join(lines)


def _compare_table(rows: list[dict]) -> str:
    from bench.gap_baselines import SINDY_EFFECTS

    rs = [r for r in rows if "joint_lsq" in r]
    if not rs:
        return ""
    lines = ["", f"side by side on the same {len(rs)} logs (compare mode):",
             f"{'method':<26}{'all named, SNR>=3':>19}{'effect named, SNR>=3':>22}{'spurious logs':>15}"
             f"{'med spurious':>13}{'med p.err':>16}{'med gap a/b':>13}{'med pos a/b':>13}{'med wall':>10}"]
    skipped = [r["esindy"]["skipped"] for r in rs if "skipped" in r.get("esindy", {})]
    for method, label, only in (("chain", "chain", None), ("joint_lsq", "(a) joint least squares", None),
                                ("esindy", "(b) E-SINDy, all effects", None),
                                ("esindy", "(b) E-SINDy, its 8 effects", set(SINDY_EFFECTS))):
        f = figures(rs, method, only)
        if f["wall_s"][1] == 0:
            continue
        lines.append(f"{label:<26}{fmt_figure(f['multi_all_named_hi']):>19}{fmt_figure(f['multi_effect_named_hi']):>22}"
                     f"{fmt_figure(f['multi_spurious']):>15}{f['spurious_per_log']:>13.1f}{fmt_figure(f['multi_perr']):>16}"
                     f"{fmt_figure(f['gap_ratio'], False):>13}{fmt_figure(f['pos_ratio'], False):>13}{f['wall_s'][0]:>9.0f}s")
    if skipped:
        lines.append(skipped[0])
    lines.append("per log, named (spurious marked *):")
    for r in rs:
        def names(m):
            if m not in r or "skipped" in r[m]:
                return "-"
            return ", ".join(n + ("*" if n in r[m]["spurious"] else "") for n in r[m]["named"]) or "none"
        lines.append(f"  {r['trial']:>2} hidden {', '.join(r['effects'])}")
        for m in ("chain", "joint_lsq", "esindy"):
            lines.append(f"       {m:<10} {names(m)}")
    return "\n".join(lines)


def report(rows: list[dict]) -> str:
    syn = [r for r in rows if r.get("mode") in ("single", "multi", "speed_gyro", "tenth", "merged", "unmodelled",
                                                "compare")]
    parts = []
    if syn:
        parts.append(_trial_table(syn))
    for r in rows:
        if r.get("mode") == "glitch":
            g = r["glitch"]
            parts.append(f"glitch {r['trial']} ({g['kind']} at {g['t_start_s']:.1f}-{g['t_end_s']:.1f} s, listed as "
                         f"{', '.join(sorted({x[0] for x in g['listed']})) or 'nothing'}; hidden {', '.join(r['effects'])}): "
                         f"clean {', '.join(r['clean']['named']) or 'none'}; with it "
                         f"{', '.join(r['glitchy']['named']) or 'none'}"
                         + "".join(f"; {run} alike: " + ", ".join(f"{a}~{b} (z {z:+.2f})" for _, a, b, z in r[run]["alike"])
                                   for run in ("clean", "glitchy") if r[run]["alike"]))
    for r in rows:
        if r.get("mode") == "unmodelled":
            parts.append(f"unmodelled {r['trial']}: " + ("; ".join(d["text"] for d in r["leftovers"]) or "no leftover"))
    for r in rows:
        if r.get("mode") in ("real", "real_partial"):
            if "error" in r:
                parts.append(f"real {r['log']}: TRACEBACK\n{r['error']}")
                continue
            steps = "; ".join(f"+{e} held-out gap {a:.3g} -> {b:.3g}" for _, e, a, b in r["steps"]) or "no effect kept"
            rmse = ", ".join(f"{sig} {r['rmse_before'][sig]:.3f} -> {r['rmse_after'].get(sig, float('nan')):.3f}"
                             for sig in ("position_m", "speed_mps", "yaw_rate_radps") if sig in r["rmse_before"])
            sd = r.get("parameter_sigma", {})
            values = ", ".join(f"{f} = {v:.4g}" + sigma_text(sd.get(f)) for f, v in r["parameters"].items())
            parts.append(f"real {r['log']} ({r['wall_s']:.0f} s wall, signals {', '.join(r['signals'])}): kept "
                         f"{', '.join(r['effects']) or 'none'} ({values})\n  held-out gap {r['gap_before']:.3g} -> "
                         f"{r['gap_after']:.3g}; RMSE {rmse}\n  steps: {steps}\n  stop: {r['stop']}")
        if r.get("mode") == "timing":
            parts.append(f"timing: {r['log_s']:.0f}-s log, hidden {r['hidden']}, {r['jobs']} processes: "
                         f"{r['wall_s']:.0f} s wall; kept {', '.join(r['effects']) or 'none'} {r['parameters']}")
    merged = [r for r in rows if "rows_held" in r]
    if merged:
        parts.append(_rows_held_table(merged))
    cmp_ = _compare_table(rows)
    if cmp_:
        parts.append(cmp_)
    t = target_rows(rows)
    if t:
        lines = ["", f"{'mode':<13}{'target':<58}{'figure':<26}{'goal':<18}met"]
        for x in t:
            met = "-" if x["met"] is None else ("met" if x["met"] else "NOT met")
            lines.append(f"{x['mode']:<13}{x['target']:<58}{x['text']:<26}{x['goal']:<18}{met}")
        parts.append("\n".join(lines))
    return "\n".join(parts)


# --- bench/results/gap.json: the figures docs/gap.md shows (``--results``) ----------------------------

RESULTS = Path(__file__).resolve().parent / "results" / "gap.json"
RESULTS_FORMAT = "nxpcup-bench-results/1"  # what tools/render_bench_tables.py reads
_COMPARE_FIGURES = (("multi_all_named_hi", "every effect named, logs where each has SNR >= 3", "share"),
                    ("multi_effect_named_hi", "effects named where SNR >= 3", "share"),
                    ("multi_spurious", "logs with a spurious effect", "share"),
                    ("multi_perr", "median parameter error", "error"),
                    ("gap_ratio", "median held-out gap after/before", "ratio"),
                    ("pos_ratio", "median held-out position RMSE after/before", "ratio"),
                    ("wall_s", "median wall time per log", "seconds"))
_METHODS = (("chain", "chain"), ("joint_lsq", "joint least squares"), ("esindy", "E-SINDy"))


def _result_kind(target: dict) -> tuple[str, str]:
    """``(kind, detail)`` of a :func:`target_rows` row: how the render script writes its figure."""
    mode, what = target["mode"], target["target"]
    if mode == "timing":
        return "seconds", ""
    if mode in ("real", "real_partial"):
        if what.endswith("after/before"):
            return "ratio", ""
        return ("ratio" if "RMSE" in what else "text"), target["text"]
    for m, key, w, _, _, pct in SYNTH_TARGETS:
        if (m, w) == (mode, what):
            return ("error" if key.endswith("perr") else "share" if pct else "ratio"), ""
    return "share", ""  # unmodelled, glitch


def results_data(rows: list[dict], modes: list[str], run: dict, old: dict | None = None) -> dict:
    """The results file after a run of ``modes`` (``rows``: its rows; ``run``: ``command``,
    ``date``, ``commit``, ``wall_min``, ``jobs``, ``note``): one row per target of
    :func:`target_rows` (and per figure and method of the ``compare`` side by side), which
    replace ``old``'s rows of the same modes; a mode the run gave no rows keeps its old ones."""
    def label(mode: str) -> str:  # the multi targets of a compare run are the compare logs'
        return "compare" if mode == "multi" and "multi" not in modes else mode

    def trials(mode: str) -> str:
        group = ("multi", "compare") if mode in ("multi", "compare") else (mode,)
        ks = sorted({r["trial"] for r in rows if r.get("mode") in group and "trial" in r})
        if ks and ks == list(range(ks[0], ks[-1] + 1)):
            return f"{ks[0]}-{ks[-1]}" if len(ks) > 1 else str(ks[0])
        return ",".join(map(str, ks))

    def finite(x) -> float | None:
        return float(x) if x is not None and math.isfinite(x) else None

    rid = f"{run['date']} {'+'.join(modes)}"
    new = []
    for t in target_rows(rows):
        kind, detail = _result_kind(t)
        new.append({"mode": label(t["mode"]), "trials": trials(t["mode"]), "target": t["target"], "kind": kind,
                    "value": finite(t["figure"]), "n": t["n"], "detail": detail, "goal": t["goal"], "met": t["met"],
                    "run": rid})
    side = [r for r in rows if "joint_lsq" in r]
    if side:
        figs = {method: figures(side, method) for method, _ in _METHODS}
        for key, what, kind in _COMPARE_FIGURES:
            for method, name in _METHODS:
                value, n = figs[method][key]
                new.append({"mode": "compare", "trials": trials("compare"), "target": what, "kind": kind,
                            "value": finite(value), "n": n, "detail": "", "goal": "reported", "met": None,
                            "run": rid, "method": name})
    done = {r["mode"] for r in new}
    order = {m: i for i, m in enumerate(MODES)}
    kept = [r for r in (old or {}).get("rows", []) if r["mode"] not in done]
    all_rows = sorted(kept + new, key=lambda r: order.get(r["mode"], len(order)))
    runs = {**(old or {}).get("runs", {}), rid: run}
    return {"format": RESULTS_FORMAT, "bench": "gap",
            "about": (old or {}).get("about", "The gap bench's latest figure of every target; rendered into "
                                              "docs/gap.md by tools/render_bench_tables.py."),
            "runs": {k: v for k, v in runs.items() if any(r["run"] == k for r in all_rows)}, "rows": all_rows}


def write_results(path: Path, rows: list[dict], modes: list[str], argv: list[str], wall_s: float, jobs: int) -> None:
    """:func:`results_data` of this run into ``path`` (its old content merged), with the
    command line, today's date (UTC) and the commit (marked when the tree had changes)."""
    import datetime
    import shlex
    import subprocess

    def git(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=Path(__file__).resolve().parents[1], capture_output=True,
                                  text=True, check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return ""

    commit = git("rev-parse", "--short", "HEAD") or "unknown"
    if git("status", "--porcelain", "--untracked-files=no"):
        commit += " with uncommitted changes"
    run = {"command": " ".join(["python -m bench.bench_gap", *map(shlex.quote, argv)]),
           "date": datetime.datetime.now(datetime.timezone.utc).date().isoformat(), "commit": commit,
           "wall_min": round(wall_s / 60.0, 1), "jobs": jobs, "note": ""}
    old = json.loads(path.read_text()) if path.exists() else None
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(results_data(rows, modes, run, old), indent=1, default=float) + "\n")


# --- command line ------------------------------------------------------------------------------------

def pooled_rows(paths: list[Path]) -> list[dict]:
    """The rows of several ``--out`` files, a trial run twice counted once (the later file's;
    a ``compare`` trial is its ``multi`` trial with the baselines, and replaces it)."""
    rows: dict[tuple, dict] = {}
    for path in paths:
        for r in json.loads(path.read_text())["rows"]:
            rows[(r["mode"], r.get("trial", r.get("log")))] = r
    for _, k in [key for key in rows if key[0] == "compare"]:
        rows.pop(("multi", k), None)
    return sorted_rows(rows.values())


def sorted_rows(rows) -> list[dict]:
    """Rows in the order of :data:`MODES`, then by trial."""
    order = {m: i for i, m in enumerate(MODES)}
    return sorted(rows, key=lambda r: (order[r["mode"]], r.get("trial", 0)))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description="gap workflow bench (issue 10 targets)")
    ap.add_argument("--mode", default=",".join(MODES), help=f"comma-separated, of {', '.join(MODES)}")
    ap.add_argument("--trials", type=int, default=SMALL_TRIALS, help="trials per synthetic mode")
    ap.add_argument("--only", type=lambda t: [int(x) for x in t.split(",") if x.strip()], default=None,
                    help="comma-separated trial numbers (instead of --first/--trials: to re-run the "
                         "trials a change can affect)")
    ap.add_argument("--first", type=int, default=0,
                    help="number of the first trial (to add trials to an earlier run's sample)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--screen", type=float, default=None, metavar="SECONDS",
                    help="run_gap's screen_max_s (default: the chain's; 0: all fit windows)")
    ap.add_argument("--out", type=Path, default=None, help="write the rows and targets (JSON)")
    ap.add_argument("--results", type=Path, nargs="?", const=RESULTS, default=None, metavar="FILE.json",
                    help="after the run, put its targets into FILE.json (default bench/results/gap.json; "
                         "then python tools/render_bench_tables.py)")
    ap.add_argument("--table", type=Path, nargs="+", default=None,
                    help="only print the tables of --out files (their rows pooled)")
    a = ap.parse_args([] if argv is None else argv)
    if a.table:
        print(report(pooled_rows(a.table)))
        return
    modes = [m.strip() for m in a.mode.split(",") if m.strip()]
    bad = [m for m in modes if m not in MODES]
    if bad:
        ap.error(f"unknown mode(s) {', '.join(bad)} (expected {', '.join(MODES)})")
    rows: list[dict] = []
    t_start = time.perf_counter()

    def save() -> None:  # after every row: a run cut short keeps what it did (``--table`` reads it)
        if a.out:
            done = sorted_rows(rows)
            a.out.write_text(json.dumps({"argv": sys.argv[1:] if argv is None else argv, "rows": done,
                                         "targets": target_rows(done)}, indent=1, default=float) + "\n")
    if "timing" in modes:
        rows.append(timing_row(a.jobs))
        save()
        print(f"[timing done, {time.perf_counter() - t_start:.0f} s]", file=sys.stderr, flush=True)
    if "real" in modes:
        if not (REAL_DIR / REAL_CAR).exists():
            print(f"[real: no shared real logs at {REAL_DIR} (set NXPCUP_REAL_LOGS): skipped]", file=sys.stderr)
        for r in real_rows(a.jobs, screen_max_s=a.screen):
            rows.append(r)
            save()
            print(f"[real {r['log']} done, {r['wall_s']:.0f} s]", file=sys.stderr, flush=True)
    if "real_partial" in modes:
        if not (REAL_DIR / REAL_CAR).exists():
            print(f"[real_partial: no shared real logs at {REAL_DIR} (set NXPCUP_REAL_LOGS): skipped]",
                  file=sys.stderr)
        for r in real_partial_rows(a.jobs, screen_max_s=a.screen):
            rows.append(r)
            save()
            print(f"[real_partial {r['log']} done, {r['wall_s']:.0f} s]", file=sys.stderr, flush=True)
    tasks, trials = [], (a.only if a.only is not None else range(a.first, a.first + a.trials))
    if "compare" in modes:
        tasks += [("compare", k, True) for k in trials]
    elif "multi" in modes:
        tasks += [("multi", k, False) for k in trials]
    tasks += [(m, k, False) for m in ("single", "speed_gyro", "tenth", "merged", "unmodelled", "glitch") if m in modes
              for k in trials]
    if tasks:
        with ProcessPoolExecutor(max_workers=a.jobs) as pool:
            futures = {pool.submit(_trial, *t, a.screen): t for t in tasks}
            for fut in as_completed(futures):
                row = fut.result()
                rows.append(row)
                save()
                print(f"[{row['mode']} {row['trial']} done, {row['wall_s']:.0f} s; "
                      f"{time.perf_counter() - t_start:.0f} s total]", file=sys.stderr, flush=True)
    rows = sorted_rows(rows)
    save()  # first: a failing report must not lose hours of rows
    if a.results:
        write_results(a.results, rows, modes, list(argv or []), time.perf_counter() - t_start, a.jobs)
        print(f"[results: {a.results}]", file=sys.stderr, flush=True)
    text = report(rows)
    print(text)
    print(f"\nbench wall time: {time.perf_counter() - t_start:.0f} s on {a.jobs} processes")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: `bench` importable
    main(sys.argv[1:])
