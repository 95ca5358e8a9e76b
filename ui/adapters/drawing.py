"""Posture drawing: projected markers and skeleton lines per view, a frame's detections
and keypoints, the blank canvas of a keypoint project without video (no Qt).

The drawing adapters call :func:`kinematics.model.fk.forward_kinematics` and each camera's
``project``; they never compute kinematics themselves."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from kinematics.model import Body
from kinematics.model.fk import forward_kinematics
from kinematics.model.histograms import wrap_deg


# -- posture drawing ------------------------------------------------------------------------
@dataclass(frozen=True)
class Skeleton:
    """Lines of a body drawn between its 3D points.

    ``edges`` index rows of ``points`` = ``[joints; segment ends]`` as
    :func:`skeleton_points` stacks them: a joint centre to the distal end of each of its
    segments, and a segment end to a child joint translated away from it.
    """

    n_joints: int
    edges: np.ndarray  # (n_edges, 2) int64


def skeleton(body: Body) -> Skeleton:
    """The edges of ``body`` (see :class:`Skeleton`)."""
    joint_index = {name: k for k, name in enumerate(body.joint_names)}
    nj = len(joint_index)
    edges = []
    for s, (joint, seg) in enumerate(body.segments()):
        edges.append((joint_index[joint.name], nj + s))
        for child in seg.joints:
            if any(child.translation):
                edges.append((nj + s, joint_index[child.name]))
    return Skeleton(nj, np.array(edges, dtype=np.int64).reshape(-1, 2))


@dataclass(frozen=True)
class PostureGeometry:
    """3D points of one posture (world units)."""

    markers: np.ndarray  # (n_markers, 3)
    points: np.ndarray  # (n_joints + n_segments, 3): joints, then segment ends
    edges: np.ndarray  # (n_edges, 2) rows of ``points``

    def lines(self) -> np.ndarray:
        """Endpoints of the skeleton lines, shape (2 * n_edges, 3), pairwise."""
        return self.points[self.edges.ravel()]


def angle_distance(a_deg, b_deg) -> float:
    """Distance of two postures in degrees: the norm of their axis differences, each
    wrapped to ±180°."""
    return float(np.linalg.norm(wrap_deg(np.asarray(a_deg, float) - np.asarray(b_deg, float))))


def posture_geometry(body: Body, angles_deg, roots=None) -> PostureGeometry:
    """Forward kinematics (Eq. 1 and 2) of one posture, as points and skeleton lines.

    Parameters
    ----------
    angles_deg : array_like, shape (n_axes,)
    roots : array_like, shape (n_chains, 3), optional
        Root positions; default the chains' configured ones.
    """
    pose = forward_kinematics(body, np.asarray(angles_deg, dtype=float), roots)
    return PostureGeometry(pose.markers, np.concatenate([pose.joints, pose.segment_ends]),
                           skeleton(body).edges)


@dataclass(frozen=True)
class ViewOverlay:
    """What one video view draws of the model: projected markers and skeleton lines, in the
    view image's pixels (the cameras' coordinates)."""

    markers: np.ndarray  # (n_markers, 2)
    lines: np.ndarray  # (2 * n_edges, 2), pairs of endpoints


def project_geometry(geometry: PostureGeometry, cameras: Sequence) -> list[ViewOverlay]:
    """Project a posture through each view's camera (``camera.project``)."""
    lines3 = geometry.lines()
    return [ViewOverlay(cam.project(geometry.markers), cam.project(lines3)) for cam in cameras]


def view_overlays(body: Body, cameras: Sequence, angles_deg, roots=None) -> list[ViewOverlay]:
    """:func:`posture_geometry` projected into every view."""
    return project_geometry(posture_geometry(body, angles_deg, roots), cameras)


def matched_points(overlays: Sequence[ViewOverlay], detections: Sequence) -> np.ndarray:
    """(n_views, n_markers, 2) the detection each drawn model marker is measured to in each
    view: its nearest (Eq. 5's term); NaN where the view has no detection."""
    n_markers = max((len(o.markers) for o in overlays), default=0)
    out = np.full((len(overlays), n_markers, 2), np.nan)
    for v, (overlay, pts) in enumerate(zip(overlays, detections, strict=False)):
        pts = np.asarray(pts, float).reshape(-1, 2)
        if len(pts) and len(overlay.markers):
            d = np.asarray(overlay.markers, float)[:, None] - pts[None]
            out[v, :len(overlay.markers)] = pts[np.argmin(np.hypot(d[..., 0], d[..., 1]),
                                                          axis=1)]
    return out


def residuals_of(overlays: Sequence[ViewOverlay], matched: np.ndarray) -> np.ndarray:
    """(n_views, n_markers) distance of each drawn model marker to its ``matched`` point
    (:func:`matched_points`, :func:`own_keypoints`; NaN rows give NaN)."""
    out = np.full(matched.shape[:2], np.nan)
    for v, overlay in enumerate(overlays[:matched.shape[0]]):
        m = min(len(overlay.markers), matched.shape[1])
        d = np.asarray(overlay.markers, float)[:m] - matched[v, :m]
        out[v, :m] = np.hypot(d[:, 0], d[:, 1])
    return out


def body_reach(body: Body) -> float:
    """How far any point of the body can get from its chain's root (world units): the sum of
    segment lengths and joint translations plus the largest marker offset."""
    length = sum(s.length for _, s in body.segments())
    length += sum(float(np.linalg.norm(j.translation)) for _, j, _, _ in body.joints())
    offsets = [float(np.linalg.norm(m.offset)) for _, _, m in body.markers()]
    return length + max(offsets, default=0.0)


def frame_detections(detections, record: int, n_views: int) -> list[np.ndarray]:
    """Detected centroids of one record, one (n, 2) array per view; empty arrays when there
    are no detections or the record is outside them."""
    if detections is None or not 0 <= record < detections.n_records:
        return [np.empty((0, 2)) for _ in range(n_views)]
    return [np.asarray(detections.points_of(record, v)) for v in range(n_views)]


def frame_keypoints(mapped, record: int, marker_names: Sequence[str]) -> list[np.ndarray]:
    """A keypoint project's 2D keypoints of one record, one (n_markers, 3) array of x, y,
    score per view, rows in the order of ``marker_names`` (the chain's markers); NaN where
    missing, filtered out, below the score threshold or without a keypoint.

    ``mapped`` is a :class:`videotrack.markerless.route.MappedKeypoints`.
    """
    where = {name: k for k, name in enumerate(marker_names)}
    rows = [where.get(m, -1) for m in mapped.markers]
    keep = [k for k, r in enumerate(rows) if r >= 0]
    out = []
    for v in range(len(mapped.view_names)):
        kp = np.full((len(marker_names), 3), np.nan)
        if 0 <= record < mapped.xy.shape[1]:
            kp[[rows[k] for k in keep], :2] = mapped.xy[v, record, keep]
            kp[[rows[k] for k in keep], 2] = mapped.score[v, record, keep]
        kp[~np.isfinite(kp[:, :2]).all(axis=1)] = np.nan
        out.append(kp)
    return out


def own_keypoints(overlays: Sequence[ViewOverlay], keypoints: Sequence) -> np.ndarray:
    """(n_views, n_markers, 2) each drawn model marker's own keypoint in each view (NaN where
    missing): :func:`matched_points` for labelled keypoints."""
    n_markers = max((len(o.markers) for o in overlays), default=0)
    out = np.full((len(overlays), n_markers, 2), np.nan)
    for v, (overlay, kp) in enumerate(zip(overlays, keypoints, strict=False)):
        m = min(len(overlay.markers), len(kp))
        out[v, :m] = np.asarray(kp, float)[:m, :2]
    return out


def keypoint_box(xy, margin: float = 0.25) -> tuple[float, float, float, float] | None:
    """(x0, x1, y0, y1) around every keypoint ``xy`` (..., 2) of a view, widened by
    ``margin`` of its size on each side (at least 20 px): where the animal is; None
    without keypoints."""
    pts = np.asarray(xy, float).reshape(-1, 2)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) == 0:
        return None
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = np.maximum(margin * (hi - lo), 20.0)
    return float(lo[0] - pad[0]), float(hi[0] + pad[0]), float(lo[1] - pad[1]), \
        float(hi[1] + pad[1])


#: Grey level of the blank canvas a keypoint project is drawn on without its video.
CANVAS_GREY = 40
#: Blank canvas size without a calibrated image size or keypoints (VGA).
CANVAS_DEFAULT = (640, 480)


def canvas_size(image_size, xy=None, margin: float = 0.05) -> tuple[int, int]:
    """(width, height) of the blank canvas of a view without video: the camera's image size
    when calibrated with one, else the keypoints' extent (``xy`` (..., 2) pixels from the
    image's top-left corner) with a margin, else :data:`CANVAS_DEFAULT`."""
    if image_size is not None:
        return int(image_size[0]), int(image_size[1])
    pts = np.empty((0, 2)) if xy is None else np.asarray(xy, float).reshape(-1, 2)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) == 0:
        return CANVAS_DEFAULT
    far = np.maximum(pts.max(axis=0), 1.0) * (1 + margin)
    return int(np.ceil(far[0])) + 1, int(np.ceil(far[1])) + 1


