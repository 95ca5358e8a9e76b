"""The markerless route: labelled 2D keypoints of other tools read, filtered, aligned and
mapped to the chain's markers, or triangulated to 3D points."""
