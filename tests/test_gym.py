"""NXPCup-v0 (simrunner.gym): Gymnasium's checker, vector environments, determinism, the
same physics as ``simrunner drive``, reward / termination / truncation, render, bad input.
The progress tracker's geometry has property tests. Gymnasium is an optional extra."""
from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

gymnasium = pytest.importorskip("gymnasium")

import simrunner.gym  # noqa: E402,F401 - registers NXPCup-v0
from simrunner.errors import SimError  # noqa: E402
from simrunner.gym.env import NXPCupEnv  # noqa: E402
from simrunner.track.progress import CentrelineProgress  # noqa: E402
from simrunner.run.runner import default_track, drive  # noqa: E402
from vehicle.description import CarDescription  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
W = 128


def follow(obs: np.ndarray, state: dict) -> np.ndarray:
    """A small line follower on the observation (the middle of the white run, PD)."""
    idx = np.flatnonzero(obs[:W] > 0.5)
    centre = 0.5 * (idx[0] + idx[-1]) if len(idx) else W / 2 - 0.5
    err = (centre - (W / 2 - 0.5)) / (W / 2)
    u = -(0.8 * err + 0.9 * (err - state.get("prev", 0.0)))
    state["prev"] = err
    return np.array([u / 0.4, -0.2], np.float32)


@pytest.fixture(scope="module")
def env():
    e = gymnasium.make("NXPCup-v0", time_limit_s=4.0)
    yield e.unwrapped
    e.close()


# -- Gymnasium's contract -------------------------------------------------------------------
def test_env_checker_passes(env):
    from gymnasium.utils.env_checker import check_env

    check_env(env)  # determinism of reset(seed), spaces, render, step after reset


def test_spaces_are_documented_boxes(env):
    assert env.action_space == gymnasium.spaces.Box(-1.0, 1.0, (2,), np.float32)
    assert env.observation_space.shape == (W + 2,) and env.observation_space.dtype == np.float32
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert obs[-2] == 0.0 and obs[-1] == 0.0  # at rest, wheels straight
    assert (obs[:W] == 1.0).all()  # the line camera's power-up frame reads full (docs/gym.md)
    assert info["t_s"] == 0.0 and info["laps_completed"] == 0 and not info["off_track"]
    # past power-up: the lane is bright in the middle of the row, the floor dark at the sides
    base = CarDescription()
    awake = NXPCupEnv(car=base.replace(camera=dataclasses.replace(base.camera, startup_frames=0)))
    obs, _ = awake.reset(seed=0)
    assert obs[W // 2] > 0.75 and obs[0] < 0.3 and obs[W - 1] < 0.3


VEC_ACTIONS = np.array([[0.1, 0.5], [-0.2, 0.0]], np.float32)


def _vec_run(mode: str) -> np.ndarray:
    vec = gymnasium.make_vec("NXPCup-v0", num_envs=2, vectorization_mode=mode, time_limit_s=0.3)
    try:
        obs, _ = vec.reset(seed=[5, 6])
        out = [obs]
        for _ in range(18):  # past the 15-step time limit: the envs reset themselves
            obs, reward, term, trunc, info = vec.step(VEC_ACTIONS)
            out.append(obs)
        return np.stack(out)
    finally:
        vec.close()


@pytest.fixture(scope="module")
def sync_run():
    return _vec_run("sync")


def test_make_vec_sync_steps_each_env_as_a_single_env(sync_run):
    assert sync_run.shape == (19, 2, W + 2)
    single = NXPCupEnv(time_limit_s=0.3)
    for i, seed in enumerate((5, 6)):
        rows = [single.reset(seed=seed)[0]]
        for _ in range(15):
            obs, r, te, tr, _ = single.step(VEC_ACTIONS[i])
            rows.append(obs)
        assert tr and not te  # 15 frames of 20 ms
        np.testing.assert_array_equal(sync_run[:16, i], np.stack(rows))


def test_make_vec_async_gives_the_sync_observations_bit_for_bit(sync_run):
    np.testing.assert_array_equal(_vec_run("async"), sync_run)


def test_same_seed_and_actions_give_bit_identical_observations():
    rng = np.random.default_rng(1)
    actions = rng.uniform(-0.5, 0.5, size=(60, 2)).astype(np.float32)

    def run(env):
        out = [np.append(env.reset(seed=42)[0], 0.0)]
        for a in actions:
            obs, r, te, tr, info = env.step(a)
            out.append(np.append(obs, r))
            if te or tr:
                break
        return np.stack(out)

    base = CarDescription()  # a line camera with visible temporal noise (~2.5 grey levels)
    car = base.replace(camera=dataclasses.replace(base.camera, dark_noise_e=60000.0))
    a, b = NXPCupEnv(car=car, time_limit_s=2.0), NXPCupEnv(car=car, time_limit_s=2.0)
    first = run(a)
    run(a)  # an episode in between: the car state is restored exactly at reset
    np.testing.assert_array_equal(run(a), first)
    np.testing.assert_array_equal(run(b), first)
    b.reset(seed=43)
    for a in actions[:3]:  # past the power-up frame
        other_seed = b.step(a)[0]
    assert not np.array_equal(other_seed, first[3, :-1])  # the camera noise differs


def test_a_step_is_the_physics_drive_runs_between_two_camera_frames():
    """The same commands through ``drive`` (a controller calling set_speed_and_servo and
    get_image(row)) and through the environment: identical poses and rows, bit for bit."""
    steers = [0.05 * math.sin(i / 7.0) for i in range(45)]
    speeds = [1.2] * 45
    rows, pose_rows = [], []

    def main(spinner):
        for steer, speed in zip(steers, speeds):
            spinner.set_speed_and_servo(speed, steer)
            rows.append(spinner.get_image(spinner.line_row, add_noise=False)[0].copy())

    result = drive(main, time_limit_s=5.0)
    env = NXPCupEnv(camera_noise=False, speed_min_mps=0.0, speed_max_mps=2.4)
    env.reset(seed=0)
    for steer, speed in zip(steers, speeds):
        action = np.array([steer / env.car.steering.limit_rad, speed / 1.2 - 1.0])
        obs, r, te, tr, info = env.step(action)
        assert not (te or tr)
        pose_rows.append((info["x_m"], info["y_m"], info["yaw_rad"], info["speed_mps"]))
        np.testing.assert_array_equal(np.rint(obs[:W] * 255).astype(np.uint8), rows[len(pose_rows) - 1])
    log = result.log
    got = np.array(pose_rows)
    want = np.column_stack([log.column(c)[1:len(got) + 1] for c in ("x_m", "y_m", "yaw_rad", "speed_mps")])
    np.testing.assert_array_equal(got, want)


# -- reward, termination, truncation ---------------------------------------------------------
def test_straight_ahead_leaves_the_track_terminated_with_the_penalty():
    env = NXPCupEnv(off_track_penalty=3.0)
    env.reset(seed=0)
    total, steps = 0.0, 0
    while True:
        obs, r, te, tr, info = env.step(np.array([0.0, 0.0], np.float32))
        steps += 1
        if te or tr:
            break
        assert r >= 0.0  # driving forward on the lane: progress
        total += r
    assert te and not tr and info["off_track"]
    assert r < -2.9  # the penalty, plus the last step's few centimetres
    assert 1.0 < info["progress_m"] < 2.5  # the figure-8's first straight, then the first bend
    with pytest.raises(SimError, match="call reset"):
        env.step(np.zeros(2, np.float32))


def test_a_lap_earns_about_the_lap_length_and_laps_terminates():
    env = NXPCupEnv(laps=1, time_limit_s=30.0)
    obs, info = env.reset(seed=0)
    state: dict = {}
    total = 0.0
    while True:
        obs, r, te, tr, info = env.step(follow(obs, state))
        total += r
        if te or tr:
            break
    assert te and info["laps_completed"] == 1 and not info["off_track"]
    lap_m = env.track.lap_length_m
    assert abs(info["progress_m"] - total) < 1e-9
    assert lap_m - 0.3 < total < lap_m + 0.5  # one lap of centreline (the gate is at the start)


def test_time_limit_truncates():
    env = NXPCupEnv(time_limit_s=0.2)
    env.reset(seed=0)
    for k in range(10):
        obs, r, te, tr, info = env.step(np.array([0.0, -1.0], np.float32))  # speed 0: stands
    assert tr and not te and info["t_s"] == pytest.approx(0.2)
    assert abs(info["progress_m"]) < 1e-3


def test_render_returns_the_debug_frame_as_rgb():
    env = NXPCupEnv(render_mode="rgb_array", time_limit_s=1.0)
    assert env.render() is None  # nothing to draw before reset
    env.reset(seed=0)
    first = env.render()
    for _ in range(20):
        env.step(np.array([0.3, 0.5], np.float32))
    later = env.render()
    assert first.shape == later.shape == (576, 1024, 3) and first.dtype == np.uint8
    assert not np.array_equal(first, later)
    assert NXPCupEnv(time_limit_s=1.0).render() is None  # render_mode None


# -- bad input -----------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, match", [
    ({"speed_max": 2}, "unknown setting.*speed_max"),
    ({"dt_s": 0.05}, r"dt_s = 0.05: expected a number in \(0, 0.02\]"),
    ({"laps": 0}, "laps = 0: expected a whole number >= 1"),
    ({"speed_min_mps": 2.0, "speed_max_mps": 1.0}, "speed_max_mps = 1: expected more than"),
    ({"line_row": 500}, "line_row = 500: expected a row 0..127"),
    ({"camera_noise": 1}, "camera_noise = 1: expected True or False"),
    ({"random_start": "yes"}, "random_start = 'yes': expected True or False"),
    ({"render_mode": "human"}, "render_mode = 'human'"),
    ({"track": "no/such/track.txt"}, "no such track"),
    ({"track": 3}, "track = 3: expected a path"),
    ({"track": "random:x"}, None),  # random tracks are drawn at reset
])
def test_bad_settings_are_one_line_errors(kwargs, match):
    if match is None:
        env = NXPCupEnv(**kwargs)
        with pytest.raises(SimError, match="random:SEED"):
            env.reset(seed=0)
        return
    with pytest.raises(SimError, match=match) as info:
        NXPCupEnv(**kwargs)
    assert "\n" not in str(info.value)


def test_a_world_without_centreline_is_refused(tmp_path):
    nxp = Path("/work/shared/tracks/nxp_raceway")
    if not nxp.exists():
        pytest.skip("NXP's tracks are not on this machine")
    with pytest.raises(SimError, match="no centreline"):
        NXPCupEnv(track=nxp)


def test_reset_options_and_actions_are_checked():
    env = NXPCupEnv(time_limit_s=1.0)
    with pytest.raises(SimError, match="before the first reset"):
        env.step([0.0, 0.0])
    with pytest.raises(SimError, match="unknown option.*lap"):
        env.reset(options={"lap": 1})
    env.reset(seed=0, options={"track": str(default_track())})
    for bad in ([math.nan, 0.0], [1.0], "ab", None, [0.0, math.inf]):
        with pytest.raises(SimError, match="expected 2 finite numbers"):
            env.step(bad)
    obs, *_ = env.step([5.0, -5.0])  # clipped to [-1, 1]
    assert env._command == (0.0, env.car.steering.limit_rad)


def test_random_tracks_come_from_the_reset_seed():
    pytest.importorskip("trackgen.random")
    env = NXPCupEnv(track="random", time_limit_s=1.0)
    o1, i1 = env.reset(seed=3)
    o2, i2 = env.reset(seed=3)
    o3, i3 = env.reset(seed=4)
    assert i1["track"] == i2["track"] != i3["track"] and i1["track"].startswith("random:")
    np.testing.assert_array_equal(o1, o2)


def test_a_random_track_is_the_layout_of_a_seed_drawn_from_the_reset_generator(monkeypatch):
    """The plumbing of ``track="random"`` with a stand-in ``trackgen.random`` (two layouts by
    the seed's parity): the seed comes from ``env.np_random``, the options are passed on."""
    import types

    calls = []
    texts = [(ROOT / "examples" / "oval_start.txt").read_text(), default_track().read_text()]

    def random_layout(seed, *, car=None, **options):
        calls.append((seed, options))
        return texts[seed % 2]

    monkeypatch.setitem(sys.modules, "trackgen.random", types.SimpleNamespace(random_layout=random_layout))
    env = NXPCupEnv(track="random", random_track_options={"length_m": (8, 20)}, time_limit_s=1.0)
    seeds = []
    for seed in (1, 2, 3, 1):
        obs, info = env.reset(seed=seed)
        seeds.append(int(np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed))).integers(0, 2**31 - 1)))
        assert info["track"] == f"random:{seeds[-1]}"
        assert env.track.lap_length_m == pytest.approx(13.0 if seeds[-1] % 2 == 0 else 14.74, abs=0.3)
    assert [c[0] for c in calls] == seeds[:3]  # the fourth reset reuses the loaded track
    assert all(c[1] == {"length_m": (8, 20)} for c in calls)
    env.reset(seed=5, options={"track": "random:8"})
    assert env.track.name == "oval_start" and env._track_spec == "random:8"
    obs, info = env.reset()  # stays on random:8 (options change the spec for later episodes)
    assert info["track"] == "random:8"


def test_random_start_is_a_centreline_point_drawn_from_the_reset_seed():
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make("NXPCup-v0", random_start=True, time_limit_s=1.0).unwrapped
    check_env(env)
    starts = []
    for seed in (0, 1, 2, 3):
        obs, info = env.reset(seed=seed)
        again, info2 = env.reset(seed=seed)
        pose = (info["x_m"], info["y_m"], info["yaw_rad"])
        assert np.array_equal(obs, again) and pose == (info2["x_m"], info2["y_m"], info2["yaw_rad"])
        assert abs(info["lateral_m"]) < 1e-6 and not info["off_track"]
        assert abs(info["speed_mps"]) < 1e-3 and info["t_s"] == 0.0
        starts.append(info["s_m"])
        # it faces the driving direction: straight ahead at half speed for 0.5 s is progress
        progress = sum(env.step(np.array([0.0, 0.0], np.float32))[1] for _ in range(25))
        assert 0.1 < progress < 0.8
    assert len(set(starts)) == 4


def test_progress_point_at_walks_the_loop():
    p = CentrelineProgress(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]))
    assert p.point_at(0.5) == (0.5, 0.0, 0.0)
    assert p.point_at(1.5) == pytest.approx((1.0, 0.5, math.pi / 2))
    assert p.point_at(3.5) == pytest.approx((0.0, 0.5, -math.pi / 2))
    assert p.point_at(4.5) == p.point_at(0.5) and p.point_at(-0.5) == p.point_at(3.5)


def test_without_gymnasium_one_clear_line():
    code = ("import sys\nsys.modules['gymnasium'] = None\n"
            "try:\n    import simrunner.gym\nexcept ImportError as e:\n    print(e)\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         timeout=120)
    assert out.stdout.strip() == ("simrunner.gym needs Gymnasium, which is not installed: "
                                  "pip install 'nxpcup-sim[gym]'")


# -- progress along the centreline ---------------------------------------------------------------
def _circle(n: int, r: float = 1.0) -> np.ndarray:
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    return np.column_stack((r * np.cos(a), r * np.sin(a)))


@settings(max_examples=60, deadline=None)
@given(n=st.integers(8, 200), start=st.floats(0.0, 2 * math.pi), step=st.floats(-0.05, 0.05),
       offset=st.floats(-0.2, 0.2))
def test_progress_on_a_circle_is_the_arc_moved(n, start, step, offset):
    """Moving along a circle (inside or outside it) by ``step`` rad of angle, also across the
    seam, advances the polygon's arc length by the chord-projected amount: within the
    polygon's own error, and with the right sign."""
    pts = _circle(n)
    p = CentrelineProgress(pts)
    r = 1.0 + offset
    p.reset(r * math.cos(start), r * math.sin(start))
    total = 0.0
    for k in range(1, 41):
        a = start + k * step
        total += p.advance(r * math.cos(a), r * math.sin(a))
    perimeter = p.length_m
    want = 40 * step * perimeter / (2 * math.pi)
    sag = 1.0 - math.cos(math.pi / n)  # how far the polygon's sides sit inside the circle
    assert abs(total - want) <= 2 * (2 * math.pi / n) + abs(want) * (sag + abs(offset)) + 1e-9
    assert abs(total) <= 1e-9 or math.copysign(1.0, total) == math.copysign(1.0, step)  # rounding has no sign
    assert abs(p.lateral_m + offset) < abs(offset) * 0.1 + sag + 1e-9  # + = left = inside


def test_progress_stays_on_its_branch_where_a_figure8_crosses_itself():
    from simrunner.track import load_track
    from vehicle import CarDescription

    track = load_track(default_track(), car=CarDescription())
    c = np.asarray(track.centreline)
    p = CentrelineProgress(c)
    p.reset(*c[0])
    total = 0.0
    fine = np.concatenate([np.linspace(c[i], c[(i + 1) % len(c)], 8, endpoint=False) for i in range(len(c))])
    for x, y in fine[1:]:
        ds = p.advance(x, y)
        assert ds >= -1e-12  # never jumps back onto the other branch at the crossing
        total += ds
    total += p.advance(*c[0])
    assert total == pytest.approx(p.length_m, abs=1e-9)
    # the polyline's length: the curves' chords, within 0.1 % of the lap length
    assert p.length_m == pytest.approx(track.lap_length_m, rel=1e-3)


def test_progress_refuses_bad_centrelines():
    with pytest.raises(SimError, match="expected an"):
        CentrelineProgress(np.zeros((2, 2)))
    with pytest.raises(SimError, match="coincide"):
        CentrelineProgress(np.array([[0, 0], [1, 0], [1, 0], [0, 1.0]]))


@pytest.mark.parametrize("track, random_start", [(None, False), ("random", False), (None, True)])
def test_learning_example_smoke(tmp_path, track, random_start):
    """examples/learn_ppo.py for a few hundred steps (needs the learn extra), on the default
    track, on a new random track every episode and from random start points."""
    pytest.importorskip("stable_baselines3")
    sys.path.insert(0, str(ROOT / "examples"))
    try:
        import learn_ppo
    finally:
        sys.path.remove(str(ROOT / "examples"))
    result = learn_ppo.train(timesteps=256, minutes=5.0, out=tmp_path, n_envs=2, n_steps=128,
                             eval_time_s=1.0, track=track, random_start=random_start, verbose=False)
    assert result["steps"] == 256
    assert result["eval_track"].startswith("random:") == (track == "random")
    for name in ("learning_curve.png", "episodes.csv", "policy.zip", "evaluation.txt"):
        assert (tmp_path / name).stat().st_size > 0
    assert "eval_progress_m" in (tmp_path / "evaluation.txt").read_text()


def test_a_linescan_car_observes_its_physical_camera_at_its_frame_period():
    import dataclasses

    from vehicle.description import CarDescription

    base = CarDescription()
    car = base.replace(camera=dataclasses.replace(base.camera, model="linescan", exposure_s=0.0095,
                                                  startup_frames=1))
    env = NXPCupEnv(car=car, time_limit_s=1.0)
    obs, info = env.reset(seed=3)
    assert env.metadata["render_fps"] == pytest.approx(100.0)
    assert (obs[:128] == 1.0).all()  # frame 0 and 1: the power-up frames read full
    obs, *_ = env.step(np.array([0.0, -0.5], np.float32))
    assert info["t_s"] == 0.0 and env._clock.time_s == pytest.approx(0.01)  # 9.5 + 0.5 ms
    assert (obs[:128] == 1.0).all()
    obs, *_ = env.step(np.array([0.0, -0.5], np.float32))
    lane = obs[:128]
    assert lane.max() < 1.0 and lane[64] > 0.3 and lane[0] < 0.5 * lane[64]  # lit, not clipped, vignetted
    again = NXPCupEnv(car=car, time_limit_s=1.0)
    again.reset(seed=3)
    again.step(np.array([0.0, -0.5], np.float32))
    assert np.array_equal(again.step(np.array([0.0, -0.5], np.float32))[0], obs)
    ideal = NXPCupEnv(car=base.replace(camera=dataclasses.replace(base.camera, model="ideal")), time_limit_s=1.0)
    assert ideal.metadata["render_fps"] == pytest.approx(50.0)
    assert ideal.reset(seed=3)[0][64] == pytest.approx(235 / 255, abs=0.1)  # the exact render, noisy
