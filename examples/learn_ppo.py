"""Train a PPO policy (stable-baselines3) to drive NXPCup-v0 on the default track (or a
new random track every episode: ``--track random``; from random points of the track:
``--random-start``), and plot its learning curve.

Needs the learning extra: ``pip install 'nxpcup-sim[learn]'`` (stable-baselines3, which
needs PyTorch; a CPU build is enough: ``pip install torch --index-url
https://download.pytorch.org/whl/cpu`` first if pip would otherwise fetch a CUDA one).

Run it::

    python examples/learn_ppo.py --minutes 30 -o ppo_run
    python examples/learn_ppo.py --minutes 30 --track random --random-start -o ppo_random

It trains until ``--timesteps`` environment steps or ``--minutes`` of wall time, whichever
comes first, then drives the learnt policy once (deterministic actions, no exploration) on
the same track - with ``--track random``, on a random track drawn from the seed ``--seed`` +
10000 - from the track's start pose (``--eval-time`` seconds) and writes to the output
folder:

- ``learning_curve.png``: episode return (metres of progress, minus penalties) and laps per
  episode against environment steps, with the wall time on the top axis;
- ``episodes.csv``: one row per training episode (steps, wall_s, return, length_s,
  laps, off_track);
- ``policy.zip``: the trained policy (``stable_baselines3.PPO.load``);
- ``evaluation.txt``: what the final policy did (laps, lap times, progress, how it ended).

Everything is seeded (``--seed``): the same command gives the same policy when run with the
same library versions on one thread.
"""
from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path


def _imports():
    try:
        import torch
        from stable_baselines3 import PPO
        from stable_baselines3.common.callbacks import BaseCallback
        from stable_baselines3.common.monitor import Monitor
        from stable_baselines3.common.vec_env import DummyVecEnv
    except ModuleNotFoundError as exc:
        sys.exit(f"learn_ppo.py needs {exc.name}, which is not installed: pip install 'nxpcup-sim[learn]'")
    return torch, PPO, BaseCallback, Monitor, DummyVecEnv


def make_env(env_kwargs: dict):
    import gymnasium

    import simrunner.gym  # noqa: F401 - registers NXPCup-v0

    return gymnasium.make("NXPCup-v0", **env_kwargs)


def train(*, timesteps: int, minutes: float, out: Path, seed: int = 0, n_envs: int = 4,
          time_limit_s: float = 20.0, speed_max_mps: float = 2.5, n_steps: int = 512,
          eval_time_s: float = 60.0, track: str | None = None, random_start: bool = False,
          verbose: bool = True) -> dict:
    """Train, save, plot and evaluate; returns the evaluation (a dict). ``track``: the
    environment's track (docs/gym.md: None = the default track, a path, ``"random"`` = a new
    random track every episode, ``"random:N"``); ``random_start``: episodes start at random
    points of the track (the evaluation starts at the track's start pose)."""
    torch, PPO, BaseCallback, Monitor, DummyVecEnv = _imports()
    torch.set_num_threads(1)
    out.mkdir(parents=True, exist_ok=True)
    env_kwargs = {"time_limit_s": time_limit_s, "speed_max_mps": speed_max_mps, "laps": None,
                  "track": track, "random_start": random_start}
    episodes: list[dict] = []
    t0 = time.perf_counter()

    class Record(BaseCallback):
        """Collects finished episodes; stops at the wall-time budget."""

        def _on_step(self) -> bool:
            for info, done in zip(self.locals["infos"], self.locals["dones"]):
                if done and "episode" in info:
                    episodes.append({"steps": self.num_timesteps,
                                     "wall_s": round(time.perf_counter() - t0, 2),
                                     "return": round(float(info["episode"]["r"]), 4),
                                     "length_s": round(float(info["t_s"]), 2),
                                     "laps": int(info["laps_completed"]),
                                     "off_track": bool(info["off_track"])})
                    if verbose and len(episodes) % 20 == 0:
                        recent = episodes[-20:]
                        print(f"{self.num_timesteps:8d} steps {episodes[-1]['wall_s']:7.0f} s  "
                              f"mean return {sum(e['return'] for e in recent) / 20:7.2f}  "
                              f"laps {sum(e['laps'] for e in recent) / 20:4.2f}  "
                              f"off track {sum(e['off_track'] for e in recent) / 20:4.2f}", flush=True)
            return time.perf_counter() - t0 < minutes * 60.0

    venv = DummyVecEnv([lambda: Monitor(make_env(env_kwargs),
                                        info_keywords=("t_s", "laps_completed", "off_track"))
                        for _ in range(n_envs)])
    venv.seed(seed)  # environment i: seed + i
    model = PPO("MlpPolicy", venv, seed=seed, n_steps=n_steps, batch_size=min(256, n_steps * n_envs), n_epochs=10,
                learning_rate=3e-4, gamma=0.99, gae_lambda=0.95, clip_range=0.2, ent_coef=0.0,
                policy_kwargs={"net_arch": [64, 64]}, device="cpu", verbose=0)
    model.learn(total_timesteps=timesteps, callback=Record())
    train_s = time.perf_counter() - t0
    model.save(out / "policy.zip")
    with open(out / "episodes.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=["steps", "wall_s", "return", "length_s", "laps", "off_track"])
        w.writeheader()
        w.writerows(episodes)
    result = evaluate(model, {**env_kwargs, "time_limit_s": eval_time_s, "random_start": False}, seed)
    result.update(steps=int(model.num_timesteps), train_wall_s=round(train_s, 1),
                  episodes=len(episodes))
    (out / "evaluation.txt").write_text("".join(f"{k}: {v}\n" for k, v in result.items()))
    what = ("default track" if track is None else track) + (", random starts" if random_start else "")
    plot(episodes, out / "learning_curve.png", result, what)
    return result


def evaluate(model, env_kwargs: dict, seed: int) -> dict:
    """One episode of the deterministic policy on the training track (for ``"random"``, the
    random track of the reset seed ``seed + 10000``)."""
    env = make_env(env_kwargs)
    obs, info = env.reset(seed=seed + 10_000)
    ret, done = 0.0, False
    while not done:
        action, _ = model.predict(obs, deterministic=True)
        obs, r, term, trunc, info = env.step(action)
        ret += r
        done = term or trunc
    return {"eval_track": info["track"], "eval_return": round(ret, 3), "eval_progress_m": round(info["progress_m"], 2),
            "eval_laps": info["laps_completed"], "eval_lap_times_s": [round(t, 3) for t in info["lap_times_s"]],
            "eval_ended": "off track" if info["off_track"] else f"time limit {info['t_s']:g} s"}


def plot(episodes: list[dict], path: Path, result: dict, track: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    if episodes:
        steps = np.array([e["steps"] for e in episodes])
        ret = np.array([e["return"] for e in episodes])
        laps = np.array([e["laps"] for e in episodes])
        k = max(1, min(20, len(episodes) // 5))
        smooth = np.convolve(ret, np.ones(k) / k, mode="valid")
        ax1.plot(steps, ret, ".", ms=2, alpha=0.4, label="episode")
        ax1.plot(steps[k - 1:], smooth, "-", label=f"mean of {k}")
        ax2.plot(steps, laps, ".", ms=2, alpha=0.4)
        ax2.plot(steps[k - 1:], np.convolve(laps, np.ones(k) / k, mode="valid"), "-")
    if len({e["wall_s"] for e in episodes}) >= 2:   # a wall-time axis needs two times
        minutes = [e["wall_s"] / 60 for e in episodes]
        top = ax1.secondary_xaxis("top", functions=(lambda s: np.interp(s, steps, minutes),
                                                    lambda m: np.interp(m, minutes, steps)))
        top.set_xlabel("wall time (min)")
    ax1.set_ylabel("return (m of progress)")
    ax1.legend(loc="upper left")
    ax2.set_ylabel("laps per episode")
    ax2.set_xlabel("environment steps (50 Hz)")
    fig.suptitle(f"PPO on NXPCup-v0 ({track}): final policy {result['eval_laps']} lap(s), "
                 f"{result['eval_progress_m']} m, {result['eval_ended']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--timesteps", type=int, default=1_000_000, help="environment steps at most")
    p.add_argument("--minutes", type=float, default=30.0, help="wall-time budget of the training")
    p.add_argument("-o", "--out", type=Path, default=Path("ppo_run"), help="output folder")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--envs", type=int, default=4, help="environments stepped together (one process)")
    p.add_argument("--speed-max", type=float, default=2.5, help="speed of the action +1 (m/s)")
    p.add_argument("--eval-time", type=float, default=60.0, help="length of the final drive (s)")
    p.add_argument("--track", default=None, help="the track: a layout path, 'random' (a new random "
                   "track every episode) or 'random:N' (default: the bundled track)")
    p.add_argument("--random-start", action="store_true",
                   help="start episodes at random points of the track (not only its start pose)")
    a = p.parse_args(argv)
    result = train(timesteps=a.timesteps, minutes=a.minutes, out=a.out, seed=a.seed,
                   n_envs=a.envs, speed_max_mps=a.speed_max, eval_time_s=a.eval_time, track=a.track,
                   random_start=a.random_start)
    for k, v in result.items():
        print(f"{k}: {v}")


if __name__ == "__main__":
    main()
