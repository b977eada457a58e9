"""Cost of the effects layer (issue 4, issue 10): ``make_sim`` steps per CPU-second for the
nominal car (a plain CarSim), a static effect only (steering offset: no sub-step), the other
command-time effects (speed scale, steering asymmetry, steering play: no sub-step), the
build-time scales (accel, brake, servo rate, steering limit, mass: a plain EffectSim around a
differently built car), the ESC brake-before-reverse (checked at each command, sub-stepped
only while it brakes; the bench drives forward, so this is its cost when it does not act),
four-wheel drive (``front_drive``: two more wheel servos in the physics), and filtered effects (latency + lags + drag: sub-step every 4 ms), each driving with a new command every 20 ms for 4 simulated seconds at
dt 2 ms; plus the CPU time of one excitation-plan play-back (``run_plan``, ~67 s simulated).
Best of 3, CPU time."""
from __future__ import annotations

import math
import time

from simrunner.car.effects import make_sim, with_effects
from simrunner.workflows.excite import make_plan, run_plan
from vehicle.description import CarDescription

SIM_S = 4.0
REPEATS = 3


def _rate(car) -> float:
    best = math.inf
    for _ in range(REPEATS):
        sim = make_sim(car)
        t0 = time.process_time()
        for k in range(round(SIM_S / 0.02)):
            sim.set_command(1.5, 0.2 * math.sin(0.05 * k))
            sim.step(10)
        best = min(best, time.process_time() - t0)
    return round(SIM_S / 0.002) / best


def main() -> None:
    car = CarDescription()
    rows = [("nominal (CarSim)", car),
            ("steering_offset only", with_effects(car, steering_offset_rad=0.02)),
            ("speed_scale+asym+play", with_effects(car, speed_scale=0.95, steering_asymmetry=0.05,
                                                   steering_play_rad=0.02)),
            ("build scales", with_effects(car, accel_scale=0.9, brake_scale=1.1, servo_rate_scale=0.8,
                                          steer_limit_scale=0.95, mass_scale=1.1)),
            ("esc_reverse_delay", with_effects(car, esc_reverse_delay_s=0.2)),
            ("lift_lag", with_effects(car, lift_lag_s=0.5)),
            ("front_drive (4WD)", with_effects(car, front_share_shift=0.5)),
            ("latency+lags+drag", with_effects(car, command_latency_s=0.03, steering_lag_s=0.05,
                                               motor_lag_s=0.1, drag_coeff_kgpm=0.1))]
    print(f"{'car':24s} {'steps/CPU-s':>12s} {'x real time':>12s}")
    for name, c in rows:
        r = _rate(c)
        print(f"{name:24s} {r:12.0f} {r * 0.002:12.1f}")
    plan = make_plan(car)
    t0 = time.process_time()
    run_plan(plan, car)
    print(f"run_plan nominal, {plan.duration_s:.0f} s plan at dt 2 ms: {time.process_time() - t0:.2f} CPU-s")
