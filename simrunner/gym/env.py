"""``NXPCup-v0``: the NXP Cup car on a track as a Gymnasium environment (docs/gym.md).

Built from the same parts as ``simrunner drive`` - the car model (``simrunner.car.make_sim``),
the lockstep clock (:class:`~simrunner.run.clock.LockstepClock`), the camera's line kernel
and the :class:`~simrunner.run.judge.Judge` - so a step is the physics a controller gets
between two ``get_image(row)`` calls: one camera frame (50 Hz for the default car), the
command set before the frame's first physics step. Same seed, same actions: bit-identical
observations. Randomness comes only from ``self.np_random`` (seeded by ``reset``): the
camera noise, the seed of a random track and (``random_start``) the start point.

Spaces (``W`` = camera width, 128 for the default car):

- action ``Box(-1, 1, (2,), float32)``: ``[steer, speed]``. ``steer`` x the car's
  ``steering.limit_rad`` is the bicycle steering angle (+ = left); ``speed`` maps linearly
  from -1 -> ``speed_min_mps`` to +1 -> ``speed_max_mps`` (default 0 .. the car's
  ``drive.max_speed_mps``). Values outside [-1, 1] are clipped; NaN raises.
- observation ``Box(float32, (W + 2,))``: the line camera row (``line_row``) as gray / 255
  (0 = black, 1 = white; column 0 = the car's left), then ``speed_mps / speed_scale`` and
  ``steer_rad / steering.limit_rad`` (actual, not commanded), both clipped to [-2, 2];
  ``speed_scale`` = ``speed_max_mps`` (or 1 m/s if that is <= 0).

Reward per step: metres advanced along the track's centreline (negative backwards), minus
``off_track_penalty`` on the step that leaves the track. ``terminated``: a wheel left the road
(the judge of ``drive``), or ``laps`` laps completed; ``truncated``: ``time_limit_s`` of
simulated time reached.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from pieces.pose import Pose2
from simrunner.car import CarModel, make_sim
from simrunner.errors import SimError
from simrunner.gym import tracks
from simrunner.track.progress import CentrelineProgress
from simrunner.gym.settings import EnvSettings
from simrunner.run.clock import LockstepClock
from simrunner.run.judge import Judge
from simrunner.run.spinner import BufferedNormals
from simrunner.sensors.camera import Camera
from simrunner.track import SimTrack
from vehicle.description import CarDescription, load_car

_NEVER = 1 << 30  # the judge's lap count when laps=None (no lap ends an episode)
_MAX_CACHED_TRACKS = 8
_OBS_CLIP = 2.0


@dataclass
class _TrackParts:
    """What a track needs, built once and reused by every episode on it."""

    track: SimTrack
    label: str
    sim: CarModel
    initial: Any  # sim.save_state() at the start pose, at rest
    camera: Camera
    progress: CentrelineProgress
    imager: Any = None  # the physical camera (camera.model linescan / area), else None


class NXPCupEnv(gymnasium.Env):
    """The NXP Cup car following a track; see the module docstring (and docs/gym.md).

    ``track``: a track spec (:mod:`simrunner.gym.tracks`: None = the default figure-8, a
    path, ``"random"``, ``"random:N"``, a ``SimTrack``); ``reset(options={"track": spec})``
    changes it for that and later episodes. ``car``: a car TOML path or
    ``CarDescription`` (None: the default car). ``random_track_options``: keywords for
    ``trackgen.random.random_layout``. Other keywords: the fields of :class:`EnvSettings`.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(self, *, track: tracks.TrackSpec = None, car: str | Path | CarDescription | None = None,
                 render_mode: str | None = None, random_track_options: dict | None = None,
                 **settings: Any):
        unknown = sorted(set(settings) - set(EnvSettings.names()))
        if unknown:
            raise SimError(f"NXPCup-v0: unknown setting(s) {', '.join(unknown)} (expected track, car, "
                           f"render_mode, random_track_options, {', '.join(EnvSettings.names())})")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise SimError(f"render_mode = {render_mode!r}: expected None or 'rgb_array'")
        self.settings = s = EnvSettings(**settings)
        self.car = car if isinstance(car, CarDescription) else load_car(car)
        self.render_mode = render_mode
        self._random_options = dict(random_track_options or {})
        cam = self.car.camera
        self._width = int(cam.width_px)
        self.line_row = cam.default_row if s.line_row is None else s.line_row
        if not 0 <= self.line_row < cam.height_px:
            raise SimError(f"line_row = {self.line_row}: expected a row 0..{cam.height_px - 1}")
        self._frame_period_s = cam.frame_period_s()  # a linescan camera: exposure + read-out
        self.metadata = {**self.metadata, "render_fps": 1.0 / self._frame_period_s}
        self._steer_limit_rad = float(self.car.steering.limit_rad)
        self._wheelbase_m = float(self.car.chassis.wheelbase_m)
        self._v_min = s.speed_min_mps
        self._v_max = float(self.car.drive.max_speed_mps) if s.speed_max_mps is None else s.speed_max_mps
        if self._v_max <= self._v_min:
            raise SimError(f"speed_min_mps = {self._v_min:g}: expected less than speed_max_mps = {self._v_max:g}")
        self._speed_scale = self._v_max if self._v_max > 0 else 1.0
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        low = np.zeros(self._width + 2, np.float32)
        high = np.ones(self._width + 2, np.float32)
        low[-2:], high[-2:] = -_OBS_CLIP, _OBS_CLIP
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self._lut = (np.arange(256, dtype=np.float32) / np.float32(255.0))
        self._track_spec = track
        self._cache: dict[Any, _TrackParts] = {}
        self._parts: _TrackParts | None = None
        self._clock: LockstepClock | None = None
        self._done = True
        if not tracks.is_random(track):  # a random track is drawn at reset
            self._parts_for(track)  # bad input fails here, not at the first reset

    # -- tracks ----------------------------------------------------------------------------
    def _parts_for(self, spec: tracks.TrackSpec) -> _TrackParts:
        key = tracks.cache_key(spec)
        parts = self._cache.get(key)
        if parts is None:
            track, label = tracks.load(spec, self.car, self._random_options)
            sim = make_sim(self.car, dt_s=self.settings.dt_s, start=track.start,
                           surface_z_m=track.surface_z_m, terrain=track.terrain)
            camera = Camera(self.car.camera, track)
            imager = None
            if self.car.camera.model != "ideal":
                from simrunner.sensors.imaging import Imager

                imager = Imager(camera, track.lighting, surface_z_m=track.surface_z_m)
            parts = _TrackParts(track, label, sim, sim.save_state(), camera,
                                CentrelineProgress(track.centreline), imager)
            if len(self._cache) >= _MAX_CACHED_TRACKS:
                self._cache.pop(next(iter(self._cache)))
            self._cache[key] = parts
        return parts

    @property
    def track(self) -> SimTrack | None:
        """The track of the current episode (None before the first reset)."""
        return None if self._parts is None else self._parts.track

    # -- Gymnasium API ---------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = sorted(set(options) - {"track"})
        if unknown:
            raise SimError(f"reset(options=...): unknown option(s) {', '.join(unknown)} (expected track)")
        if "track" in options:
            self._track_spec = options["track"]
        parts = self._parts = self._parts_for(tracks.concrete_spec(self._track_spec, self.np_random))
        sim = parts.sim
        sim.restore_state(parts.initial)
        if self.settings.random_start:
            x_m, y_m, heading_rad = parts.progress.point_at(
                float(self.np_random.uniform(0.0, parts.progress.length_m)))
            sim.set_state(Pose2(x_m, y_m, heading_rad), 0.0)
        self._sim = sim
        self._clock = LockstepClock(sim, dt_s=self.settings.dt_s, frame_period_s=self._frame_period_s)
        laps = self.settings.laps
        self._judge = Judge(parts.track, laps=_NEVER if laps is None else laps)
        self._laps_goal = laps
        self._normals = BufferedNormals(self.np_random) if self.settings.camera_noise else None
        pose = self._clock.pose()
        self._judge.update(0.0, pose, sim.wheel_contacts())
        parts.progress.reset(pose.x_m, pose.y_m)
        self._progress_total_m = 0.0
        self._command = (0.0, 0.0)
        self._done = False
        self._view = None
        self._last_reward = 0.0
        self._return = 0.0
        return self._observe(pose), self._info(pose)

    def step(self, action):
        if self._done:
            raise SimError("step() after the episode ended (or before the first reset): call reset()")
        try:
            a = action.tolist() if isinstance(action, np.ndarray) else list(action)
            steer_a, speed_a = (float(v) for v in (a if len(a) == 2 else ()))
        except (TypeError, ValueError):
            steer_a = speed_a = math.nan
        if not (steer_a - steer_a == 0.0 and speed_a - speed_a == 0.0):  # NaN, inf or unusable
            raise SimError(f"step(action={action!r}): expected 2 finite numbers [steer, speed] in [-1, 1]")
        steer_a = min(max(steer_a, -1.0), 1.0)
        speed_a = min(max(speed_a, -1.0), 1.0)
        steer_rad = steer_a * self._steer_limit_rad
        speed_mps = self._v_min + 0.5 * (speed_a + 1.0) * (self._v_max - self._v_min)
        # the Spinner's default differential (thesis eq. 5.2/5.3)
        clock = self._clock
        clock.command(speed_mps, steer_rad, speed_mps * math.sin(steer_rad) / self._wheelbase_m)
        self._command = (speed_mps, steer_rad)
        clock.advance_to_next_frame()
        pose = clock.pose()
        t_s = clock.time_s
        judge = self._judge
        judge.update(t_s, pose, self._sim.wheel_contacts())
        ds = self._parts.progress.advance(pose.x_m, pose.y_m)
        self._progress_total_m += ds
        off = judge.off_track
        reward = ds - (self.settings.off_track_penalty if off else 0.0)
        terminated = off or (self._laps_goal is not None and judge.laps_completed >= self._laps_goal)
        truncated = not terminated and t_s >= self.settings.time_limit_s - 1e-9
        self._done = terminated or truncated
        self._last_reward = reward
        self._return += reward
        return self._observe(pose), float(reward), bool(terminated), bool(truncated), self._info(pose)

    def render(self):
        if self.render_mode is None or self._parts is None:
            return None
        parts, clock = self._parts, self._clock
        if self._view is None:
            from simrunner.gym.render import EpisodeView

            ch = self.car.chassis
            self._view = EpisodeView(parts.track.raster, camera=parts.camera, line_row=self.line_row,
                                     car_length_m=ch.wheelbase_m + 0.05, car_width_m=ch.track_m)
        pose = clock.pose()
        line = np.rint(self._last_obs[:self._width] * 255.0).astype(np.uint8).reshape(1, -1)
        state = {"speed": self._sim.speed_mps, "steer": self._sim.steer_rad,
                 "speed_cmd": self._command[0], "steer_cmd": self._command[1],
                 "lap": self._judge.laps_completed, "off_track": self._judge.off_track,
                 "laps": self._laps_goal if self._laps_goal is not None else "-"}
        text = (f"track {parts.track.name}"[:34], f"reward {self._last_reward:+.4f}",
                f"return {self._return:+.3f}", f"progress {self._progress_total_m:.2f} m",
                f"lateral {parts.progress.lateral_m:+.3f} m")
        return self._view.frame(k=clock.frame_index, t_s=clock.time_s, pose=pose, line=line,
                                state=state, text=text)

    # -- observation and info ----------------------------------------------------------------
    def _observe(self, pose) -> np.ndarray:
        imager = self._parts.imager
        if imager is None:
            row = self._parts.camera.line_image(pose, self.line_row, self._normals)
        else:  # the physical camera at the car file's exposure, blurred by the car's motion,
            sim = self._sim  # powered up with the episode (its first frames read full, as in drive)
            row = imager.line(pose, self.line_row, exposure_s=self.car.camera.exposure_s,
                              twist=(sim.speed_mps, sim.lateral_speed_mps, sim.yaw_rate_radps),
                              normals=self._normals, frame_index=self._clock.frame_index)
        obs = np.empty(self._width + 2, np.float32)
        obs[:self._width] = self._lut[row[0]]
        sim = self._sim
        obs[-2] = min(max(sim.speed_mps / self._speed_scale, -_OBS_CLIP), _OBS_CLIP)
        obs[-1] = min(max(sim.steer_rad / self._steer_limit_rad, -_OBS_CLIP), _OBS_CLIP)
        self._last_obs = obs
        return obs

    def _info(self, pose) -> dict:
        judge, progress = self._judge, self._parts.progress
        return {"t_s": self._clock.time_s, "x_m": pose.x_m, "y_m": pose.y_m, "yaw_rad": pose.yaw_rad,
                "speed_mps": self._sim.speed_mps, "steer_rad": self._sim.steer_rad,
                "s_m": progress.s_m, "lateral_m": progress.lateral_m,
                "progress_m": self._progress_total_m, "laps_completed": judge.laps_completed,
                "lap_times_s": judge.lap_times_s, "off_track": judge.off_track,
                "track": self._parts.label}
