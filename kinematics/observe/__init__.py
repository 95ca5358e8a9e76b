"""What the fitter is fitted to: observations of every kind (unlabelled points per view,
labelled 2D keypoints, labelled 3D points, clouds), triangulation, and the clouds of
unlabelled detections triangulated per frame."""
