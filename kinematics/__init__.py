"""Kinematic chains, histograms, forward kinematics, cameras and the annealing fitter."""

from kinematics._kernels import cache as _numba_cache  # noqa: F401  (numba's cache, first)
