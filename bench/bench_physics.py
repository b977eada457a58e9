"""Physics speed of the default car (issue 3 section 12, bare-physics half).

Rows: wheel collision shape x time step x loop:
* ``bare``: ``world.step(False)`` in a loop (car driving a steady circle at 2 m/s);
* ``CarSim.step``: the same through ``CarSim.step(n)`` (one call per 20 ms);
* ``+cmd 20ms``: ``set_command`` with a new steering target every 20 ms, plus the reads the
  runner does (pose, speed, wheel contacts).
Each figure is the best of 3 runs of 4 simulated seconds: steps per CPU-second of this
process and the real-time factor (simulated / CPU time). CPU time equals wall time on an
idle core and is much less disturbed by other jobs on a shared machine.
"""
from __future__ import annotations

import math
import time

from simrunner.car.body import WheelShape
from simrunner.car.physics import CarSim
from vehicle.description import CarDescription

SIM_S = 4.0
CONTROL_S = 0.02
REPEATS = 3


def _rate(make, loop) -> float:
    best = math.inf
    for _ in range(REPEATS):
        sim = make()
        sim.set_command(2.0, 0.3)
        sim.step(round(1.0 / sim.dt_s))  # reach the steady circle first
        t0 = time.process_time()
        loop(sim)
        best = min(best, time.process_time() - t0)
    return round(SIM_S / sim.dt_s) / best


def _bare(sim: CarSim) -> None:
    step = sim._world.step  # noqa: SLF001 - the bare engine rate is the point here
    for _ in range(round(SIM_S / sim.dt_s)):
        step(False)


def _carsim_step(sim: CarSim) -> None:
    per = round(CONTROL_S / sim.dt_s)
    for _ in range(round(SIM_S / CONTROL_S)):
        sim.step(per)


def _with_commands(sim: CarSim) -> None:
    per = round(CONTROL_S / sim.dt_s)
    for k in range(round(SIM_S / CONTROL_S)):
        sim.set_command(2.0, 0.3 * math.sin(0.05 * k))
        sim.step(per)
        _ = (sim.pose, sim.speed_mps, sim.wheel_contacts_xy())


def main() -> None:
    car = CarDescription()
    print(f"default car, {SIM_S:g} s driving at 2 m/s, best of {REPEATS}; one core, CPU time")
    print(f"{'wheels':9s} {'dt_ms':>5s} {'loop':14s} {'steps/s':>9s} {'x real time':>11s}")
    for shape in (WheelShape.SPHERE, WheelShape.CYLINDER):
        for dt in (0.002, 0.001):
            for name, loop in (("bare", _bare), ("CarSim.step", _carsim_step), ("+cmd 20ms", _with_commands)):
                rate = _rate(lambda: CarSim(car, dt_s=dt, wheel_shape=shape), loop)
                print(f"{shape.value:9s} {dt * 1e3:5.1f} {name:14s} {rate:9.0f} {rate * dt:11.1f}")


if __name__ == "__main__":
    main()
