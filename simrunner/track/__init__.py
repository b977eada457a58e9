"""The simulator's view of a track (:class:`SimTrack`): a top-down raster of the road, the
start pose and the lap gate; made in memory from a layout or a ``trackgen.Track``, or read
from a trackgen folder or a Gazebo world."""
from simrunner.track.load import (SimTrack, TrackLoadError, load_track, track_from_scene,
                                  track_from_trackgen)

__all__ = ["SimTrack", "TrackLoadError", "load_track", "track_from_scene", "track_from_trackgen"]
