"""The car model contract: what a run, the calibration and the gap replay ask of a car.

:class:`~simrunner.car.physics.CarSim` (the nominal dartpy car) and
:class:`~simrunner.car.effects.EffectSim` (the same car with catalogue effects on its command
path and forces) both satisfy :class:`CarModel`, each by its own methods (no forwarding).
Frames and units: docs/DESIGN.md (car body frame at the rear-axle midpoint; radians;
steering positive = left).
"""
from __future__ import annotations

from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np

from pieces.pose import Pose2, Pose3
from vehicle.description import CarDescription


@runtime_checkable
class CarModel(Protocol):
    """A steppable car. Commands act from the next physics step; read-outs are of the state
    after the last step."""

    car: CarDescription  # the description the model was built from
    terrain: Any         # the hills it drives over (worlds.terrain.Terrain; empty: flat)

    @property
    def dt_s(self) -> float: ...                # physics step, s
    @property
    def time_s(self) -> float: ...              # simulated time, s

    # -- commands --------------------------------------------------------------------
    def set_command(self, speed_mps: float, steer_rad: float,
                    yaw_rate_radps: float | None = None) -> None: ...
    def set_coast(self, coast: bool) -> None: ...
    def set_motors(self, left: float, right: float) -> None: ...   # rear motors' duty (duty drive)
    def set_wheel_lock(self, locked: bool) -> None: ...
    def apply_external_force_n(self, fx_n: float, fy_n: float) -> None: ...
    def step(self, n: int = 1) -> None: ...

    # -- commands as given (clamped to the car's limits) -------------------------------
    @property
    def speed_cmd_mps(self) -> float: ...
    @property
    def steer_cmd_rad(self) -> float: ...
    @property
    def yaw_rate_cmd_radps(self) -> float: ...

    # -- read-outs -----------------------------------------------------------------------
    @property
    def pose(self) -> Pose2: ...                 # rear-axle midpoint, world frame
    @property
    def pose3(self) -> Pose3: ...                # pose with height above the surface, pitch, roll
    @property
    def z_m(self) -> float: ...
    @property
    def roll_rad(self) -> float: ...
    @property
    def pitch_rad(self) -> float: ...
    @property
    def speed_mps(self) -> float: ...            # along the car's x
    @property
    def lateral_speed_mps(self) -> float: ...    # along the car's y
    @property
    def yaw_rate_radps(self) -> float: ...
    @property
    def steer_rad(self) -> float: ...            # actual bicycle-equivalent angle
    def knuckle_angles_rad(self) -> tuple[float, float]: ...
    def wheel_contacts(self) -> list[tuple[float, float]]: ...   # FL, FR, RL, RR world xy
    def wheel_contacts_xy(self) -> np.ndarray: ...              # the same, (4, 2)
    def wheel_speeds_radps(self) -> np.ndarray: ...
    @property
    def duties(self) -> tuple[float, float]: ...                 # rear motors' duties in force
    @property
    def duty_cmd(self) -> float: ...                             # set_command's one duty (NaN: set_motors')
    def wheel_angles_rad(self) -> list[float]: ...               # FL, FR, RL, RR turned since the start
    def wheel_angle_rad(self, i: int) -> float: ...              # wheel i's (0..3) of wheel_angles_rad
    def imu_truth(self, point_m: Any) -> tuple[np.ndarray, np.ndarray]: ...  # body-frame rates, specific force
    def imu_reader(self, point_m: Any) -> Callable[[], tuple]: ...  # imu_truth at point_m, no arguments

    # -- state -------------------------------------------------------------------------
    def save_state(self) -> Any: ...
    def restore_state(self, state: Any) -> None: ...
    def set_state(self, pose: Pose2, speed_mps: float, steer_rad: float = 0.0,
                  yaw_rate_radps: float = 0.0) -> None: ...
    def place(self, pose: Pose2, speed_mps: float, steer_rad: float = 0.0,
              yaw_rate_radps: float = 0.0) -> None: ...
    def prime_steering(self, t_s: Any, steer_cmd_rad: Any) -> None: ...  # state earlier commands leave

    # -- objects on the track ------------------------------------------------------------
    def add_solid(self, solid: Any) -> None: ...                 # a worlds.solids.Solid, a rigid body
    def touched_solids(self) -> tuple[str, ...]: ...             # names the car has touched


def protocol_members() -> tuple[str, ...]:
    """Names :class:`CarModel` requires (for tests and checkers)."""
    names = [n for n in CarModel.__dict__ if not n.startswith("_")]
    return tuple(sorted(set(names) | set(getattr(CarModel, "__annotations__", {}))))
