"""The body model: chains of joints and segments with markers (Eq. 1 and 2), their
histograms, rotations, forward kinematics, the packed layout the kernels read, and the XML
files of chains and histograms.

The body records live in :mod:`kinematics.model.body` and are the package's public names.
"""

from kinematics.model.body import (
    ROOT_MODES,
    UNITS,
    Axis,
    AxisRef,
    Body,
    Chain,
    Joint,
    Marker,
    Root,
    Segment,
    Vec3,
    check_histogram_range,
    validate_body,
)

__all__ = [
    "ROOT_MODES", "UNITS", "Axis", "AxisRef", "Body", "Chain", "Joint", "Marker", "Root",
    "Segment", "Vec3", "check_histogram_range", "validate_body",
]
