"""Cameras: the models (orthographic Eq. 3, pinhole with OpenCV's distortion), their packed
arrays for the kernels, camera files, and the geometry calibration uses.

The models live in :mod:`kinematics.cameras.models` and are the package's public names.
"""

from kinematics.cameras.models import (
    DIST_COUNTS,
    ORTHONORMAL_TOL,
    AxesForm,
    Camera,
    CameraArrays,
    OrthographicCamera,
    PinholeCamera,
    describe_camera,
    pack_cameras,
    project_packed,
)

__all__ = [
    "DIST_COUNTS", "ORTHONORMAL_TOL", "AxesForm", "Camera", "CameraArrays",
    "OrthographicCamera", "PinholeCamera", "describe_camera", "pack_cameras", "project_packed",
]
