"""The disciplines (issue 49, item 3): each example controller of examples/events/ over 20
seeds, and the plain line follower on the disciplines with objects (it does not look); and
what objects and a range sensor cost a run.

Targets: each example passes in >= 19 of 20 seeds; the plain follower fails ``obstacle`` and
``emergency_brake`` in >= 19 of 20; a run with objects and a range sensor keeps >= 0.8 of the
real-time factor of the same controller's run without them (CPU time).
"""
from __future__ import annotations

import time
from pathlib import Path

from simrunner.run.runner import drive

REPO = Path(__file__).resolve().parents[1]
EVENTS = REPO / "examples" / "events"
FOLLOWER = REPO / "examples" / "line_follower.py"
SEEDS = range(20)
KIT_S = REPO / "examples" / "kit_S.txt"

RUNS = [("race", EVENTS / "race.py", {"track": KIT_S}),
        ("figure8", EVENTS / "figure8.py", {}),
        ("speed_limit", EVENTS / "speed_limit.py", {}),
        ("emergency_brake", EVENTS / "emergency_brake.py", {"car": EVENTS / "sensor_car.toml"}),
        ("obstacle", EVENTS / "obstacle.py", {"car": EVENTS / "obstacle_car.toml"})]


def _passes(event: str, controller, **kw) -> tuple[int, list[str]]:
    ok, why = 0, []
    for seed in SEEDS:
        r = drive(controller, event=event, seed=seed, **kw)
        ok += bool(r.passed and not r.penalties)
        if not (r.passed and not r.penalties):
            why.append(f"seed {seed}: {r.outcome} ({r.message})")
    return ok, why


def main() -> None:
    for event, controller, kw in RUNS:
        ok, why = _passes(event, controller, **kw)
        print(f"{event:16s} {controller.name:20s} passed (no penalty) in {ok}/{len(SEEDS)} seeds"
              + (f"; first miss: {why[0]}" if why else ""))
    for event in ("obstacle", "emergency_brake"):
        ok, _ = _passes(event, FOLLOWER)
        print(f"{event:16s} {'line_follower.py':20s} failed in {len(SEEDS) - ok}/{len(SEEDS)} seeds (target >= 19)")
    # cost of objects + a range sensor: the braking example's whole attempt (2 laps, then the
    # block and the stop) against 3 laps of the same controller and car on the same oval
    # without the event (no block: the sensor reads inf)
    from simrunner.run.events import event_track

    car = EVENTS / "sensor_car.toml"
    best = {}
    for name, run in (("same controller, no objects", lambda: drive(EVENTS / "emergency_brake.py",
                                                                    track=event_track("emergency_brake"),
                                                                    laps=3, car=car)),
                      ("emergency_brake, block + sensor", lambda: drive(EVENTS / "emergency_brake.py",
                                                                         event="emergency_brake", car=car))):
        rtf = 0.0
        for _ in range(3):
            c0 = time.process_time()
            r = run()
            rtf = max(rtf, r.sim_time_s / (time.process_time() - c0))
        best[name] = rtf
    a, b = best.values()
    print(f"closed-loop RTF (CPU, best of 3): {', '.join(f'{k} {v:.1f}x' for k, v in best.items())} "
          f"({b / a:.2f} of it; target >= 0.8)")


if __name__ == "__main__":
    main()
