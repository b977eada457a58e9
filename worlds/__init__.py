"""SDF layer: Gazebo world/model writing, world reading and checking (the car description
they write comes from ``vehicle``).

Nothing here imports dartpy (trackgen imports this package). Names load lazily (PEP 562),
so importing one part does not load the others.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # for type checkers and IDEs; at run time names load on first use
    from worlds.check import check_world
    from worlds.sdf_read import MeshVisual, Scene, load_mesh_world, read_world
    from worlds.sdf_write import write_car_model, write_track_model, write_track_world, write_world
    from worlds.sdf_xml import WorldError

_EXPORTS = {
    "WorldError": "worlds.sdf_xml",
    "Scene": "worlds.sdf_read", "MeshVisual": "worlds.sdf_read", "read_world": "worlds.sdf_read",
    "load_mesh_world": "worlds.sdf_read",
    "write_track_world": "worlds.sdf_write", "write_track_model": "worlds.sdf_write",
    "write_world": "worlds.sdf_write", "write_car_model": "worlds.sdf_write",
    "check_world": "worlds.check",
}
__all__ = list(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'worlds' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
