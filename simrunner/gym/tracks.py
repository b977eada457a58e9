"""Which track an episode drives: the ``track`` argument of the environment and of
``reset(options={"track": ...})``.

A track spec is
- ``None``: the bundled default (the thesis figure-8, as ``simrunner drive``);
- a path (``str`` or ``Path``): a layout ``.txt``, a trackgen folder, a world file or a Gazebo
  model folder, as ``simrunner drive --track`` (the track must have a centreline - layouts
  and trackgen folders have one; NXP's Gazebo worlds do not, so they cannot be used here);
- ``"random"``: a random layout from ``trackgen.random.random_layout``, its seed drawn from
  the environment's generator (``env.np_random``), so the seed given to ``reset`` fixes it;
- ``"random:N"``: the random layout of seed ``N``;
- a loaded :class:`~simrunner.track.SimTrack`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Union

import numpy as np

from simrunner.errors import SimError
from simrunner.track import SimTrack
from vehicle.description import CarDescription

TrackSpec = Union[str, Path, SimTrack, None]
RANDOM = "random"


def is_random(spec: TrackSpec) -> bool:
    return isinstance(spec, str) and (spec == RANDOM or spec.startswith(RANDOM + ":"))


def concrete_spec(spec: TrackSpec, rng: np.random.Generator) -> TrackSpec:
    """``"random"`` becomes ``"random:N"`` with ``N`` drawn from ``rng``; others unchanged."""
    if spec == RANDOM:
        return f"{RANDOM}:{int(rng.integers(0, 2**31 - 1))}"
    return spec


def cache_key(spec: TrackSpec) -> Any:
    if spec is not None and not isinstance(spec, (str, Path, SimTrack)):
        raise SimError(f"track = {spec!r}: expected a path, 'random', 'random:SEED', a SimTrack or None")
    if spec is None or isinstance(spec, SimTrack):
        return spec if spec is None else id(spec)
    if is_random(spec):
        return spec
    return str(Path(spec).resolve())


def load(spec: TrackSpec, car: CarDescription, random_options: dict | None = None) -> tuple[SimTrack, str]:
    """``(SimTrack, label)`` of a concrete spec (not plain ``"random"``). Raises
    :class:`SimError` (one line) for a bad spec or a track without a centreline."""
    if isinstance(spec, str) and spec.startswith(RANDOM + ":"):
        track, label = _random_track(spec, car, random_options or {})
    else:
        from simrunner.run.runner import resolve_track

        cache_key(spec)  # checks the type
        track, label = resolve_track(spec, car)
    if track.centreline is None or len(track.centreline) < 3:
        raise SimError(f"{label}: the track has no centreline (the reward follows it): use a layout "
                       f"(.txt) or a trackgen folder")
    return track, label


def _random_track(spec: str, car: CarDescription, options: dict) -> tuple[SimTrack, str]:
    seed_text = spec.partition(":")[2]
    try:
        seed = int(seed_text)
    except ValueError:
        raise SimError(f"track = {spec!r}: expected 'random:SEED' with a whole number SEED") from None
    try:
        from trackgen.random import random_layout
    except ImportError:
        raise SimError("track = 'random' needs trackgen.random (random layouts), which this "
                       "installation does not have") from None
    from trackgen import TrackError, parse_layout
    from trackgen.build import check_buildable
    from simrunner.track import track_from_trackgen

    label = f"{RANDOM}:{seed}"
    try:
        text = random_layout(seed, car=car, **options)
        layout = parse_layout(text, path=f"<{label}>", default_name=f"random_{seed}")
        checked = check_buildable(layout, car, meshes=False)
    except TrackError as exc:
        raise SimError(f"{label}: {exc}") from exc
    return track_from_trackgen(checked.track, geometry=checked.geometry, source=label), label
