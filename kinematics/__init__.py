"""Kinematic chains, histograms, forward kinematics, cameras and the annealing fitter."""

from kinematics import _numba_cache  # noqa: F401  (numba's cache folder, before any kernel)
