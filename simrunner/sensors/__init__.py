"""What the car sees: the line camera (an exact ground-plane projection of the track
raster) and its compiled row kernel."""
