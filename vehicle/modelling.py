"""Modelling choices shared by the two car models built from a car description: the Gazebo
model (``worlds.sdf_write``) and the dartpy car (``simrunner.car.body``). They are not
properties of a real car (the car file holds those), so they are not fields of it; one
definition here keeps the two models the same.
"""
from __future__ import annotations

KNUCKLE_MASS_FRACTION = 0.25
"""Mass of each steering knuckle / mass of a wheel: small, it keeps the joint chain
well-conditioned."""
CHASSIS_MU = 0.3
"""Friction coefficient of the chassis box (it touches the ground only in a crash)."""
