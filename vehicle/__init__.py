"""The car description: every number of the car, read by the SDF writer (``worlds``), the
track checks (``trackgen``) and the simulator (``simrunner``).

``vehicle.description`` holds the frozen :class:`CarDescription` (TOML file, units in the
field names, ranges checked at load); ``vehicle.userfiles`` reads the small text files users
write (car descriptions, measurements, plans) with one-line errors naming the file;
``vehicle.modelling`` the modelling choices both car models share (not car properties).
Nothing here imports a physics engine, OpenCV or numba. Names load on first use (PEP 562),
so ``python -m vehicle.description`` runs cleanly.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from vehicle.description import CarDescription, CarDescriptionError, Effects, car_from_dict, load_car

__all__ = ["CarDescription", "CarDescriptionError", "Effects", "car_from_dict", "load_car"]


def __getattr__(name: str):
    if name not in __all__:
        raise AttributeError(f"module 'vehicle' has no attribute {name!r}")
    value = getattr(importlib.import_module("vehicle.description"), name)
    globals()[name] = value
    return value
