"""Readers and writers of other tools' file formats (keypoints, OpenSim, C3D, movement)."""
