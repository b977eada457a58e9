"""The simulator's view of a track (:class:`SimTrack`): a top-down raster of the road, the
start pose and the lap gate; loaded from a layout, a trackgen folder or a Gazebo world."""
from simrunner.track.load import SimTrack, TrackLoadError, load_track, track_from_scene

__all__ = ["SimTrack", "TrackLoadError", "load_track", "track_from_scene"]
