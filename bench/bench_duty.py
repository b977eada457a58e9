"""Motors driven by duty (issue 51): the motor model against its closed forms, and what it costs.

1. Physics checks: a duty-driven car from rest (0 -> duty, both H-bridge modes), its steady
   speed and a coast-down with rolling resistance and drag, against the closed forms of
   ``m_eff dv/dt = 2 (c1 - c2 v) d`` (coast), ``2 (c1 d - c2 v)`` (brake) and
   ``-F_rr - k v^2`` (coast-down): the largest relative error over the sampled times (target
   <= 1 %).
2. Closed-loop real-time factor (simulated / CPU seconds, best of ``REPEATS`` interleaved runs)
   of one lap of the default track by examples/line_follower.py: the speed-commanded default
   car; a duty car (brake H-bridge, rolling resistance and drag: the motors every physics
   step, the drag every 10 ms) with a ``speed_norm`` of ``v / max_speed_mps``; both on slip
   tyres (``wheels.tyre_model = "slip"``). Target: the duty car on slip tyres >= 0.8 of the
   speed car on rigid tyres.
"""
from __future__ import annotations

import dataclasses
import importlib.util
import math
import sys
import time
from pathlib import Path

from simrunner.car.physics import CarSim
from simrunner.run.runner import drive
from vehicle.description import CarDescription

REPO = Path(__file__).resolve().parents[1]
FOLLOWER = REPO / "examples" / "line_follower.py"
REPEATS = 5
BASE = CarDescription()


def duty_car(**fields) -> CarDescription:
    return BASE.replace(drive=dataclasses.replace(BASE.drive, command="duty", **fields))


def closed_form_errors() -> dict[str, float]:
    """The largest relative speed error of each check against its closed form."""
    m_eff = CarSim(BASE).effective_mass_kg
    vmax, amax = BASE.drive.max_speed_mps, BASE.drive.max_accel_mps2
    c1 = 0.5 * m_eff * amax
    c2 = c1 / vmax
    times = [0.002, 0.1, 0.5, 1.0, 2.0, 4.0, 8.0]
    out = {}
    for hbridge, duty in (("coast", 1.0), ("coast", 0.4), ("brake", 0.4), ("brake", -0.7)):
        sim = CarSim(duty_car(hbridge=hbridge))
        sim.set_motors(duty, duty)
        v_inf = math.copysign(vmax, duty) if hbridge == "coast" else duty * vmax
        tau = vmax / amax / (abs(duty) if hbridge == "coast" else 1.0)
        worst, done = 0.0, 0
        for t in times:
            sim.step(round(t / sim.dt_s) - done)
            done = round(t / sim.dt_s)
            want = v_inf * (1.0 - math.exp(-t / tau))
            worst = max(worst, abs(sim.speed_mps - want) / abs(want))
        out[f"0 -> duty {duty:+.1f} ({hbridge})"] = worst
    f_rr, k = 0.6, 0.05
    sim = CarSim(duty_car(hbridge="coast", rolling_resistance_n=f_rr, drag_nspm2=k))
    sim.set_motors(1.0, 1.0)
    sim.step(round(8.0 / sim.dt_s))
    v0 = sim.speed_mps
    steady = (-2 * c2 + math.sqrt(4 * c2 * c2 + 4 * k * (2 * c1 - f_rr))) / (2 * k)
    out["steady speed, rolling resistance + drag"] = abs(v0 - steady) / steady
    sim.set_motors(0.0, 0.0)
    worst, done = 0.0, 0
    for t in (0.5, 1.0, 2.0, 3.0):
        sim.step(round(t / sim.dt_s) - done)
        done = round(t / sim.dt_s)
        want = math.sqrt(f_rr / k) * math.tan(math.atan(v0 * math.sqrt(k / f_rr)) - math.sqrt(f_rr * k) * t / m_eff)
        worst = max(worst, abs(sim.speed_mps - want) / want)
    out["coast-down, rolling resistance + drag"] = worst
    return out


def _follower(speed_norm=None):
    spec = importlib.util.spec_from_file_location("bench_duty_follower", FOLLOWER)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("line_follower", module)
    spec.loader.exec_module(module)

    def main(s):
        if speed_norm is not None:
            s.configure(speed_norm=speed_norm)
        module.main(s)
    return main


def _rtf(controller, **kw) -> tuple[float, object]:
    c0 = time.process_time()
    r = drive(controller, laps=1, **kw)
    return r.sim_time_s / (time.process_time() - c0), r


def main() -> None:
    for name, err in closed_form_errors().items():
        print(f"closed form, {name}: largest error {100 * err:.3f} % (target <= 1 %)")
    vmax = BASE.drive.max_speed_mps
    duty_car_ = duty_car(hbridge="brake", rolling_resistance_n=0.3, drag_nspm2=0.02)
    slip = dataclasses.replace(BASE.wheels, tyre_model="slip")
    runs = {"speed car": (_follower(), BASE),
            "duty car": (_follower(lambda v, angle: v / vmax), duty_car_),
            "speed car, slip tyres": (_follower(), BASE.replace(wheels=slip)),
            "duty car, slip tyres": (_follower(lambda v, angle: v / vmax), duty_car_.replace(wheels=slip))}
    best = {name: (0.0, None) for name in runs}
    for _ in range(REPEATS):  # interleaved: the machine's drift hits every car alike
        for name, (controller, car) in runs.items():
            rtf, r = _rtf(controller, car=car)
            if rtf > best[name][0]:
                best[name] = (rtf, r)
    base = best["speed car"][0]
    print(f"closed-loop RTF (CPU, best of {REPEATS} interleaved, one lap of the default track by the line follower):")
    for name, (rtf, r) in best.items():
        print(f"  {name}: {rtf:.1f}x ({rtf / base:.2f} of the speed car; lap {r.lap_times_s[0]:.2f} s)")
    print("  target: duty car on slip tyres >= 0.8 of the speed car on rigid tyres")


if __name__ == "__main__":
    main()
