"""Video input, marker detection, synthetic videos, projects, batch runs and the CLI."""

import kinematics  # noqa: F401  (sets numba's cache folder before videotrack's kernels)
