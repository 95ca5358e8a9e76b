"""The numba kernels (private): module-level ``@njit`` functions over arrays, no classes, no
I/O. Each has a readable NumPy twin in the public modules. :mod:`.cache` sets numba's
cache folder and must run before any kernel is decorated, so it is imported first."""

from kinematics._kernels import cache  # noqa: F401  (numba's cache folder, before any kernel)
