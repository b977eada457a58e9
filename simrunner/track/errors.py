"""The error of ``simrunner.track``: a track that cannot be read or made drivable."""
from __future__ import annotations

from simrunner.errors import SimError


class TrackLoadError(SimError, ValueError):
    """The track spec cannot be read or makes no drivable track (one line naming the file:
    an unreadable layout, world or mesh, a start off the road, a bad ``m_per_px``)."""
