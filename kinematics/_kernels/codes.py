"""Codes the kernels share: joint flags of the folded body layout, kinds of state entries,
objectives, and the empty arrays that stand for "no claims" and "no hidden marks"."""

from __future__ import annotations

import numpy as np

#: Cost of a model marker whose projection is undefined (behind a pinhole camera) when no
#: cap is set, in pixels.
NAN_MARKER_COST = 1.0e6

#: Bits of ``joint_flags`` in the folded layout.
G_IDENTITY = 1  # G_j is the identity: skip the 3×3 product
H_ZERO = 2  # h_j is zero: skip the translation
ROOT_POSE = 4  # a free root: per-frame seed rotation and state translation (slide_index)

#: Kinds of state entries (``dof_kind``): an angle whose histogram decides plausibility, or
#: a value (translation, or a free root's rotation offset) that must stay in [lo, hi].
DOF_HISTOGRAM = 0
DOF_RANGE = 1
NO_CLAIMS = np.zeros(0, np.bool_)  # the whole body: no partition claims a point
#: ``nearest`` entry of a model marker hidden in the view (:func:`hidden_in`): it takes no
#: point (:func:`takes` is false for every point) and costs nothing.
UNSEEN = -(1 << 62)
NO_HIDDEN = np.zeros((0, 4))  # a frame's obs3 without hidden marks (:func:`hidden_in`)


#: Objectives (``objective``): which error E a posture is scored by.
OBJ_NEAREST = 0  # unlabelled points per view: Eq. 5 and its variants
OBJ_LABELLED = 1  # labelled 2D keypoints: marker i of view v against its own keypoint
OBJ_POINTS3D = 2  # labelled 3D points: marker i against its own 3D point
OBJ_CLOUD = 3  # unlabelled 3D points (detections triangulated across views): nearest point
# refinement only (the final polish, Fitter._polished): the cloud paired one to one, and
# with _VIEWS a marker left without a point paired in each view with its nearest detection
OBJ_CLOUD_ONE = 4
OBJ_CLOUD_VIEWS = 5
