"""Environment speed (issue 12 target): ``NXPCup-v0`` steps per CPU-second of one core at the
50 Hz control rate, with the camera row - target >= 2000.

An episode: 20 s (1000 steps) of a small line follower (PD on the observed row) on the
default track, camera noise on, dt 2 ms (10 physics steps per env step, as ``drive``).
Only ``env.step`` is timed (the policy is the user's cost). Baseline in the same process: a
fresh car model replaying the episode's commands (``set_command`` + ``step(10)`` per frame,
nothing else), which must end at the same pose bit for bit: env / replay is the share of
physics in a step; the rest is the environment's own work (camera row, judge, progress,
observation). ``reset`` on the same track is timed too. Best of ``REPEATS``, CPU time of this
process (robust on a shared machine), wall time beside it.
"""
from __future__ import annotations

import math
import time

import numpy as np

REPEATS = 3
EPISODE_S = 20.0
TARGET_STEPS_PER_S = 2000.0


def _policy():
    prev = [0.0]

    def act(obs: np.ndarray) -> np.ndarray:
        w = len(obs) - 2
        idx = np.flatnonzero(obs[:w] > 0.5)
        centre = 0.5 * (idx[0] + idx[-1]) if len(idx) else w / 2 - 0.5
        err = (centre - (w / 2 - 0.5)) / (w / 2)
        u = -(0.8 * err + 0.9 * (err - prev[0]))
        prev[0] = err
        return np.array([u / 0.4, -0.2], np.float32)
    return act


def _episode(env) -> tuple[float, float, int, list, dict]:
    """(CPU s, wall s) inside ``env.step``, steps, the commands sent, the last info."""
    act = _policy()
    obs, info = env.reset(seed=0)
    cpu = wall = 0.0
    commands = []
    n = 0
    pc, pt = time.perf_counter, time.process_time
    while True:
        a = act(obs)
        c0, w0 = pt(), pc()
        obs, r, term, trunc, info = env.step(a)
        cpu += pt() - c0
        wall += pc() - w0
        n += 1
        commands.append(env.unwrapped._clock.current_command)  # noqa: SLF001 - for the replay
        if term or trunc:
            return cpu, wall, n, commands, info


def _replay(env, commands) -> tuple[float, float, object]:
    from simrunner.car import make_sim

    track = env.unwrapped.track
    sim = make_sim(env.unwrapped.car, dt_s=0.002, start=track.start, surface_z_m=track.surface_z_m)
    steps = round(1.0 / env.unwrapped.car.camera.fps_hz / 0.002)
    c0, w0 = time.process_time(), time.perf_counter()
    for cmd in commands:
        sim.set_command(*cmd)
        sim.step(steps)
    return time.process_time() - c0, time.perf_counter() - w0, sim.pose


def main() -> None:
    import gymnasium

    import simrunner.gym  # noqa: F401

    env = gymnasium.make("NXPCup-v0", time_limit_s=EPISODE_S)
    best_env = best_replay = (math.inf, math.inf)
    reset_cpu = math.inf
    for _ in range(REPEATS):
        cpu, wall, n, commands, info = _episode(env)
        best_env = min(best_env, (cpu / n, wall / n))
        rcpu, rwall, pose = _replay(env, commands)
        best_replay = min(best_replay, (rcpu / n, rwall / n))
        if (pose.x_m, pose.y_m, pose.yaw_rad) != (info["x_m"], info["y_m"], info["yaw_rad"]):
            raise SystemExit("bench_gym: the replay did not end at the episode's pose")
        c0 = time.process_time()
        for _ in range(20):
            env.reset(seed=1)
        reset_cpu = min(reset_cpu, (time.process_time() - c0) / 20)
    rate = 1.0 / best_env[0]
    verdict = "met" if rate >= TARGET_STEPS_PER_S else "NOT met"
    print(f"NXPCup-v0, default track, {EPISODE_S:g}-s episodes of a line follower "
          f"({n} steps, {info['laps_completed']} laps, {info['progress_m']:.1f} m), dt 2 ms, "
          f"camera row + noise; best of {REPEATS}, one core")
    print(f"{'':34s}{'us/step CPU':>12s}{'us/step wall':>13s}{'steps/s CPU':>12s}")
    print(f"{'env.step':34s}{best_env[0] * 1e6:12.1f}{best_env[1] * 1e6:13.1f}{rate:12.0f}  "
          f"target >= {TARGET_STEPS_PER_S:g}: {verdict}")
    print(f"{'replay: set_command + 10 steps':34s}{best_replay[0] * 1e6:12.1f}{best_replay[1] * 1e6:13.1f}"
          f"{1.0 / best_replay[0]:12.0f}")
    print(f"{'environment work (env - replay)':34s}{(best_env[0] - best_replay[0]) * 1e6:12.1f}")
    print(f"physics share of a step: {best_replay[0] / best_env[0]:.0%}; "
          f"real-time factor {rate / env.unwrapped.car.camera.fps_hz:.0f}x; "
          f"reset (same track): {reset_cpu * 1e3:.2f} ms CPU")
    env.close()
    from bench.record import save

    save("gym", {"repeats": REPEATS, "episode_s": EPISODE_S, "steps": n, "target_steps_per_s": TARGET_STEPS_PER_S,
                 "steps_per_s": round(rate), "step_us": round(best_env[0] * 1e6, 1),
                 "step_wall_us": round(best_env[1] * 1e6, 1), "replay_us": round(best_replay[0] * 1e6, 1),
                 "physics_share": round(best_replay[0] / best_env[0], 3), "reset_ms": round(reset_cpu * 1e3, 2)})


if __name__ == "__main__":
    main()
