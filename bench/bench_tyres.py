"""Tyres that slide (issue 51): the slip-tyre car's steady cornering against its closed forms.

1. Understeer gradient: steady turns at 0.4-1.0 m/s (and 0.6-1.5 m/s) at a fixed steering,
   ``K`` the slope of ``atan(L / R)`` over the lateral acceleration, against the single-track
   closed form ``K = (1/c_f - 1/c_r) / g`` (small angles), for the default (understeering) car
   and one with a softer rear (oversteering), at 0.02, 0.05 and 0.1 rad of steering. Target:
   within 3 % where the closed form holds (small steering angles).
2. Where it slides: stiff tyres (c = 25 per rad, mu 0.6), 0.3 rad of steering, speeds up in
   steps of 0.025 m/s until the yaw rate runs off; the steady lateral acceleration at each speed
   against :meth:`simrunner.car.tyres.SlipTyres.single_track_turn` (the single-track model on the
   same tyres, exact trigonometry, the rear driving against the front's drag in its friction
   ellipse), and the breakaway speed against :meth:`~simrunner.car.tyres.SlipTyres.single_track_limit`.
   Target: within 3 %.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from simrunner.car.physics import CarSim
from vehicle.description import CarDescription

G = 9.81


def slip_car(**wheels) -> CarDescription:
    base = CarDescription()
    return base.replace(wheels=dataclasses.replace(base.wheels, tyre_model="slip", **wheels))


def steady_turn(car: CarDescription, speed_mps: float, steer_rad: float) -> tuple[float, float, bool]:
    """``(rear-axle radius m, lateral acceleration m/s^2, steady)`` after 6.4 s at constant speed
    and steering, the rear wheels following the car's yaw rate (an open differential)."""
    sim = CarSim(car)
    sim.set_state(sim.pose, speed_mps, steer_rad)
    wheelbase = car.chassis.wheelbase_m
    yaw_rate, rates = speed_mps * math.tan(steer_rad) / wheelbase, []
    for _ in range(8):
        sim.set_command(speed_mps, steer_rad, yaw_rate)
        sim.step(400)
        yaw_rate = sim.yaw_rate_radps
        rates.append(yaw_rate)
    steady = abs(rates[-1] - rates[-2]) <= 0.01 * abs(rates[-1])
    radius = sim.speed_mps / yaw_rate
    return radius, sim.speed_mps ** 2 / radius, steady


def understeer_errors() -> list[tuple[str, float, tuple, float]]:
    """``(car, steering rad, speeds, K_sim / K_closed - 1)``."""
    out = []
    for label, front, rear in (("understeering (defaults)", 4.718, 5.4562), ("oversteering", 6.0, 4.0)):
        car = slip_car(cornering_stiffness_front_per_rad=front, cornering_stiffness_rear_per_rad=rear)
        k_closed = (1.0 / front - 1.0 / rear) / G
        for steer in (0.02, 0.05, 0.1):
            for speeds in ((0.4, 0.6, 0.8, 1.0), (0.6, 0.9, 1.2, 1.5)):
                turns = [steady_turn(car, v, steer) for v in speeds]
                a_y = [a for _, a, _ in turns]
                k = -np.polyfit(a_y, [math.atan(car.chassis.wheelbase_m / r) for r, _, _ in turns], 1)[0]
                out.append((label, steer, speeds, k / k_closed - 1.0))
    return out


def breakaway() -> dict:
    mu = 0.6
    car = slip_car(friction_mu=mu, cornering_stiffness_front_per_rad=25.0, cornering_stiffness_rear_per_rad=25.0)
    car = car.replace(drive=dataclasses.replace(car.drive, max_speed_mps=8.0, max_accel_mps2=6.0))
    tyres = CarSim(car).tyres
    limit_v, limit_a = tyres.single_track_limit(0.3)
    rows, broke = [], None
    for v in np.arange(1.5, 2.4, 0.025):
        _, a_y, steady = steady_turn(car, float(v), 0.3)
        if not steady:
            broke = float(v)
            break
        closed = tyres.single_track_turn(float(v), 0.3)[1]
        rows.append((float(v), a_y / (mu * G), closed / (mu * G)))
    return {"mu": mu, "limit_v": limit_v, "limit_a_mu_g": limit_a / (mu * G), "broke_at": broke, "rows": rows}


def main() -> None:
    print("understeer gradient K (steady turns) vs the closed form (1/c_f - 1/c_r) / g:")
    for label, steer, speeds, err in understeer_errors():
        print(f"  {label:26s} steering {steer:.2f} rad, {speeds[0]:g}-{speeds[-1]:g} m/s: {100 * err:+.2f} %"
              + ("  (target <= 3 %)" if steer <= 0.05 else "  (geometry beyond the small-angle form)"))
    b = breakaway()
    print(f"where it slides (stiff tyres, mu {b['mu']:g}, 0.3 rad): the single-track model's steady turns end at "
          f"{b['limit_v']:.3f} m/s, {b['limit_a_mu_g']:.3f} mu g; the car broke away at {b['broke_at']:.3f} m/s "
          f"({100 * (b['broke_at'] / b['limit_v'] - 1):+.1f} %; target <= 3 %, the speed step 0.025 m/s)")
    worst = 0.0
    for v, sim, closed in b["rows"]:
        if math.isfinite(closed):
            worst = max(worst, abs(sim / closed - 1))
            print(f"  {v:.3f} m/s: {sim:.3f} mu g, closed form {closed:.3f} ({100 * (sim / closed - 1):+.1f} %)")
        else:
            print(f"  {v:.3f} m/s: {sim:.3f} mu g, closed form: no steady turn")
    print(f"  largest steady difference {100 * worst:.1f} % (target <= 3 %)")


if __name__ == "__main__":
    main()
