"""What one calibration procedure gives (``simrunner calibrate``): its checks and changes,
shared by :mod:`.calibrate` and :mod:`.camera_procedures`."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from simrunner.workflows.calibration.measured import CalibrationError, Measurements
from vehicle.description import CarDescription, CarDescriptionError, car_from_dict


@dataclass(frozen=True)
class Check:
    """One compared quantity: measured on the real car, simulated before and after."""

    label: str
    unit: str
    measured: float
    before: float
    after: float


@dataclass(frozen=True)
class ProcedureResult:
    """One procedure: the car fields it changed ``{"section.field": (old, new)}``, the
    checks, and notes (derived numbers such as the speed normalisation)."""

    section: str
    title: str
    changes: dict[str, tuple[float, float]]
    checks: tuple[Check, ...]
    notes: tuple[str, ...] = ()
    values: dict[str, Any] = dataclasses.field(default_factory=dict)


def range_checked(car: CarDescription, m: Measurements, section: str) -> CarDescription:
    """The car must stay inside the description's ranges (vehicle.description)."""
    try:
        return car_from_dict(car.to_dict(), m.path)
    except CarDescriptionError as exc:
        raise CalibrationError(f"{m.path}: {section}: the result is out of range ({str(exc).split(': ', 1)[-1]})") from None
