"""Pure functions between the session's state and what the widgets draw (no Qt).

Everything here takes and returns plain arrays and small records, so it is unit-tested
without a display: projected markers and skeleton lines per view, the detections of a frame,
rows of the error table and the re-analysis highlight, timeline arrays, histogram bars, and
the body edits of the chain editor and of manual corrections (pinning axes).

The drawing adapters call :func:`kinematics.fk.forward_kinematics` and each camera's
``project``; they never compute kinematics themselves.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from kinematics.chain_xml import default_histogram
from kinematics.errors import KinematicsError
from kinematics.fk import forward_kinematics
from kinematics.histograms import Histogram, bin_centres, wrap_deg
from kinematics.model import Axis, Body, Chain, Joint, Marker, Segment

#: Table text of a frame that has not been fitted.
NOT_FITTED = "not fitted"
#: Statuses whose posture the user can trust (within the threshold, or set by hand).
GOOD_STATUSES = ("ok", "reanalysed", "corrected")


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

    ``mapped`` is a :class:`videotrack.markerless.MappedKeypoints`.
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


# -- error table and timeline ---------------------------------------------------------------
@dataclass(frozen=True)
class FrameTable:
    """Columns of the per-frame error table, one row per record (NaN where not fitted)."""

    frame: np.ndarray  # (n,) int64
    error: np.ndarray  # (n,)
    error_per_view: np.ndarray  # (n, n_views)
    runs: np.ndarray  # (n,) int64, 0 where not fitted
    status: list[str]  # (n,)


def frame_table(results: Mapping, n_frames: int, n_views: int) -> FrameTable:
    """The error table of all ``n_frames`` records from ``{frame: FrameResult}``."""
    error = np.full(n_frames, np.nan)
    per_view = np.full((n_frames, n_views), np.nan)
    runs = np.zeros(n_frames, np.int64)
    status = [NOT_FITTED] * n_frames
    for f, r in results.items():
        if 0 <= f < n_frames:
            error[f], per_view[f], runs[f], status[f] = table_row(r, n_views)
    return FrameTable(np.arange(n_frames, dtype=np.int64), error, per_view, runs, status)


def table_row(result, n_views: int) -> tuple:
    """One row ``(error, errors per view, runs, status)`` of a result (or of None)."""
    if result is None:
        return np.nan, np.full(n_views, np.nan), 0, NOT_FITTED
    return float(result.error), np.asarray(result.error_per_view, float), int(result.runs), \
        result.status


def is_bad(error, threshold: float):
    """The highlight rule: error above the re-analysis threshold (NaN is not bad)."""
    e = np.asarray(error, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(e), e > threshold, False)


def bad_frames(results: Mapping, threshold: float) -> list[int]:
    """Frames whose error exceeds ``threshold``, ascending."""
    return sorted(f for f, r in results.items() if bool(is_bad(r.error, threshold)))


#: Statuses that need a look even within the threshold.
ATTENTION_STATUSES = ("failed", "reanalysed", "ambiguous")


def frames_to_check(results: Mapping, threshold: float) -> list[int]:
    """Frames a person should look at, ascending: those above the threshold or whose fit
    failed, needed re-runs or is ambiguous (see FrameResult.status); never
    the ones corrected or accepted by hand."""
    return sorted(f for f, r in results.items() if r.status != "corrected" and (
        bool(is_bad(r.error, threshold)) or r.status in ATTENTION_STATUSES))


def next_to_check(results: Mapping, threshold: float, frame: int, direction: int
                  ) -> int | None:
    """The nearest frame after (``direction`` > 0) or before ``frame`` that needs a look."""
    todo = frames_to_check(results, threshold)
    later = [f for f in todo if (f - frame) * direction > 0]
    if not later:
        return None
    return later[0] if direction > 0 else later[-1]


@dataclass(frozen=True)
class Timeline:
    """Arrays of the timeline plot over all records."""

    frames: np.ndarray  # (n,)
    angles_deg: np.ndarray  # (n, n_axes), NaN where not fitted
    error: np.ndarray  # (n,)


def timeline(results: Mapping, n_frames: int, n_axes: int) -> Timeline:
    """Angles and error of every record from ``{frame: FrameResult}``."""
    angles = np.full((n_frames, n_axes), np.nan)
    error = np.full(n_frames, np.nan)
    for f, r in results.items():
        if 0 <= f < n_frames:
            angles[f], error[f] = r.angles_deg, r.error
    return Timeline(np.arange(n_frames, dtype=float), angles, error)


def learning_angles(results: Mapping, statuses: Sequence[str] | None = GOOD_STATUSES,
                    threshold: float | None = None) -> np.ndarray:
    """Postures to learn histograms from (Eq. 4), shape (n, n_axes), in frame order.

    ``statuses`` None takes every fitted frame. With a ``threshold`` the frames are judged by
    it instead of by their stored statuses (set by the fit's threshold): :func:`trusted`.
    Frames without a finite posture are skipped.
    """
    if threshold is not None:
        keep = [f for f in sorted(results) if trusted(results[f], threshold)]
    else:
        keep = [f for f in sorted(results) if statuses is None or results[f].status in statuses]
    rows = [np.asarray(results[f].angles_deg, float) for f in keep]
    rows = [a for a in rows if np.all(np.isfinite(a))]
    return np.array(rows).reshape(len(rows), -1) if rows else np.empty((0, 0))


#: Statuses of fitted frames whose trust the error threshold decides.
FITTED_STATUSES = ("ok", "reanalysed", "failed")


def trusted(result, threshold: float) -> bool:
    """A frame within the threshold now: corrected by hand, or fitted with E ≤ ``threshold``
    (whatever status the fit gave it under its own threshold; ambiguous frames are not)."""
    if result.status == "corrected":
        return True
    error = float(result.error)
    return result.status in FITTED_STATUSES and np.isfinite(error) and error <= threshold


# -- histograms -----------------------------------------------------------------------------
@dataclass(frozen=True)
class HistogramBars:
    """Bars of one histogram on an unwrapped degree axis, and a value marked on it."""

    centres: np.ndarray  # (n_bins,) degrees, increasing, one turn from ``centres[0]``
    heights: np.ndarray  # (n_bins,)
    width: float
    value: float | None  # the marked value on the same axis, or None
    mean: float  # the histogram's mean on the same axis
    view_range: tuple[float, float]  # degrees worth showing (the support with a margin)


def histogram_bars(hist: Histogram, value_deg: float | None = None,
                   margin_deg: float = 10.0) -> HistogramBars:
    """Bin centres unwrapped so the occupied bins are contiguous (a range such as
    [120, 220] through ±180° shows as one block), with ``value_deg`` on the same axis."""
    lo, hi = hist.support_deg()
    start = lo - (360.0 - (hi - lo)) / 2.0  # the cut lies in the middle of the empty part
    centres = bin_centres(hist.n_bins)
    x = start + (centres - start) % 360.0
    order = np.argsort(x)
    def on_axis(angle: float) -> float:
        return float(start + (angle - start) % 360.0)

    value = on_axis(value_deg) if value_deg is not None and np.isfinite(value_deg) else None
    return HistogramBars(x[order], hist.values[order], hist.bin_width_deg, value,
                         on_axis(hist.mean_deg()), (lo - margin_deg, hi + margin_deg))


# -- body edits (chain editor, manual correction) -------------------------------------------
def map_joints(body: Body, edit: Callable[[Joint], Joint]) -> Body:
    """A copy of ``body`` with ``edit`` applied to every joint, children first."""

    def walk(joint: Joint) -> Joint:
        segs = tuple(replace(s, joints=tuple(walk(c) for c in s.joints))
                     for s in joint.segments)
        return edit(replace(joint, segments=segs))

    return replace(body, chains=tuple(replace(c, root_joint=walk(c.root_joint))
                                      for c in body.chains))


def edit_joint(body: Body, name: str, **changes) -> Body:
    """Replace fields of the joint ``name`` (e.g. ``orientation_deg``, ``translation``)."""
    return map_joints(body, lambda j: replace(j, **changes) if j.name == name else j)


def edit_segment(body: Body, name: str, **changes) -> Body:
    """Replace fields of the segment ``name`` (e.g. ``length``, ``rotation_deg``)."""
    def edit(j: Joint) -> Joint:
        segs = tuple(replace(s, **changes) if s.name == name else s for s in j.segments)
        return replace(j, segments=segs)

    return map_joints(body, edit)


def edit_marker(body: Body, name: str, **changes) -> Body:
    """Replace fields of the marker ``name`` (e.g. ``offset``)."""
    def edit_seg(s: Segment) -> Segment:
        return replace(s, markers=tuple(replace(m, **changes) if m.name == name else m
                                        for m in s.markers))

    return map_joints(body, lambda j: replace(j, segments=tuple(edit_seg(s)
                                                                for s in j.segments)))


def edit_root(body: Body, chain: str, **changes) -> Body:
    """Replace fields of a chain's :class:`~kinematics.model.Root` (e.g. ``position``)."""
    return replace(body, chains=tuple(
        replace(c, root=replace(c.root, **changes)) if c.name == chain else c
        for c in body.chains))


def chain_marker_names(body: Body, chain: str) -> list[str]:
    """Names of the markers of one chain, in joint order (the choices of a root marker)."""
    ch = find_element(body, "chain", chain)
    return [] if ch is None else Body(body.name, (ch,), body.units).marker_names


def parse_window(text: str, what: str, field: str | None = None) -> float | None:
    """A root window typed by the user: empty is None (the default), else a number."""
    text = text.strip()
    if not text:
        return None
    try:
        return float(text)
    except ValueError:
        raise KinematicsError(f"{what} must be a number > 0, or empty for the default; "
                              f"got '{text}'", field=field) from None


def edit_root_settings(body: Body, chain: str, *, mode: str, position, marker: str | None,
                       translation_text: str = "", rotation_text: str = "") -> Body:
    """The chain editor's root page applied: mode (fixed, marker, free), position, root
    marker (None for none) and the free root's windows as typed (empty = default, see
    :func:`kinematics.placement.root_windows`).

    Raises :class:`~kinematics.errors.KinematicsError` for what the typed values cannot
    express (a window that is no number, a marker root without a marker); the rest is left
    to :func:`kinematics.model.validate_body`.
    """
    where = f"chain '{chain}' root"
    if mode == "marker" and marker is None:
        raise KinematicsError("a marker root follows a root marker: choose one of the "
                              "chain's markers", field=where)
    return edit_root(
        body, chain, mode=mode, position=tuple(float(v) for v in position), marker=marker,
        translation_window=parse_window(translation_text, "translation window", where),
        rotation_window_deg=parse_window(rotation_text, "rotation window", where))


def default_root_windows(body: Body, chain: str) -> tuple[float, float] | None:
    """The windows a chain's root gets when made free with empty windows, (translation,
    rotation degrees), or None when it cannot be free (no markers on its root joint's
    segments)."""
    from kinematics.placement import root_windows

    ch = find_element(body, "chain", chain)
    if ch is None or not any(s.markers for s in ch.root_joint.segments):
        return None
    free = replace(body, chains=(replace(ch, root=replace(
        ch.root, mode="free", translation_window=None, rotation_window_deg=None)),))
    try:
        w_t, w_r = root_windows(free)[0]
    except (KinematicsError, ValueError, IndexError):
        return None
    return float(w_t), float(w_r)


def root_markers(body: Body, chain: str) -> list[str]:
    """Markers on the segments of a chain's root joint: those that place a free root."""
    ch = find_element(body, "chain", chain)
    return [] if ch is None else [m.name for s in ch.root_joint.segments for m in s.markers]


def edit_axis(body: Body, index: int, *, min_deg: float | None = None,
              max_deg: float | None = None, locked_deg: float | type | None = ...) -> Body:
    """Change the range or lock of the axis at posture index ``index``.

    The axis gets its default histogram again (uniform over the new range, or the single
    bin of the locked value; :func:`kinematics.chain_xml.default_histogram`), because a
    learned histogram does not fit another range. ``locked_deg=None`` frees the axis; leave
    it out to keep the lock as it is.
    """
    ref = body.axis_refs()[index]
    a = ref.axis
    lo = a.min_deg if min_deg is None else float(min_deg)
    hi = a.max_deg if max_deg is None else float(max_deg)
    locked = a.locked_deg if locked_deg is ... else locked_deg
    new = replace(a, min_deg=lo, max_deg=hi, locked_deg=locked,
                  histogram=default_histogram(lo, hi, locked) if lo <= hi else a.histogram)
    return _replace_axis(body, index, new)


def _replace_axis(body: Body, index: int, axis: Axis) -> Body:
    ref = body.axis_refs()[index]
    k = index - 3 * (index // 3)

    def edit(j: Joint) -> Joint:
        if j.name != ref.joint:
            return j
        axes = list(j.axes)
        axes[k] = axis
        return replace(j, axes=tuple(axes))

    return map_joints(body, edit)


def free_axes(body: Body) -> list[int]:
    """Posture indices of the axes that are not locked."""
    return [r.index for r in body.axis_refs() if not r.axis.locked]


def marker_axes(body: Body, marker: int) -> list[int]:
    """Posture indices of the free axes that move marker number ``marker``: those of the
    joint carrying it and of every joint above it, root first."""
    owner = [j.name for j, _, _ in body.markers()][marker]
    parents: dict[str, str | None] = {j.name: (p.name if p is not None else None)
                                      for _, j, p, _ in body.joints()}
    chain = []
    name: str | None = owner
    while name is not None:
        chain.append(name)
        name = parents[name]
    on_path = set(chain)
    return [r.index for r in body.axis_refs() if r.joint in on_path and not r.axis.locked]


@dataclass(frozen=True)
class DragSolution:
    """The single axis change that best puts a dragged marker where it was dropped."""

    axis: int  # posture index
    value_deg: float
    residual_px: float  # distance left between the marker's projection and the target


def solve_marker_drag(body: Body, camera, angles_deg, roots, marker: int, target_xy,
                      axes: Sequence[int] | None = None, step_deg: float = 0.25
                      ) -> DragSolution | None:
    """Which one axis, turned to which angle, brings ``marker`` nearest to ``target_xy``.

    For each candidate axis (default every free axis that moves the marker,
    :func:`marker_axes`) its whole range is sampled every ``step_deg`` with the other
    angles held, the marker is placed by forward kinematics and projected by ``camera``,
    and the sample nearest the target wins; on a tie (within 0.5 px) the axis nearer the
    marker (distal) wins, since it changes least of the rest of the chain. This is a
    brute-force look-up, not a fit: the session then pins the axis and lets the fitter
    re-fit the others.

    Returns None when no free axis moves the marker.
    """
    axes = marker_axes(body, marker) if axes is None else list(axes)
    if not axes:
        return None
    base = np.asarray(angles_deg, dtype=float)
    target = np.asarray(target_xy, dtype=float)
    ranges = body.ranges_deg()
    best: DragSolution | None = None
    for index in reversed(axes):  # distal first, so it wins ties
        lo, hi = ranges[index]
        values = np.linspace(lo, hi, max(2, int(np.ceil((hi - lo) / step_deg)) + 1))
        postures = np.repeat(base[None], values.size, axis=0)
        postures[:, index] = values
        rts = body.root_positions() if roots is None else np.asarray(roots, float)
        pose = forward_kinematics(body, postures, rts)
        d = np.linalg.norm(camera.project(pose.markers[:, marker]) - target, axis=1)
        k = int(np.nanargmin(d))
        if best is None or d[k] < best.residual_px - 0.5:
            best = DragSolution(index, float(values[k]), float(d[k]))
    return best


def clamp_to_range(body: Body, angles_deg) -> np.ndarray:
    """Angles clipped into their axes' ranges, locked axes at their value."""
    a = np.clip(np.asarray(angles_deg, float), *body.ranges_deg().T)
    locked = body.locked_mask()
    return np.where(locked, body.mean_posture_deg(), a)


# -- project dialog -------------------------------------------------------------------------
@dataclass(frozen=True)
class ViewPreview:
    """One view of the filter preview: the view image, the filter chain's mask (both in view
    orientation and size) and the detected centroids."""

    image: np.ndarray  # (h, w) or (h, w, 3) uint8
    mask: np.ndarray  # (h, w) uint8, non-zero for marker pixels
    points: np.ndarray  # (n, 2)

    def overlay(self, colour=(255, 40, 220)) -> np.ndarray:
        """RGB picture: the image dimmed to grey with the mask's pixels in ``colour``."""
        grey = self.image if self.image.ndim == 2 else self.image.mean(axis=2)
        rgb = np.repeat((0.6 * grey)[..., None], 3, axis=2).astype(np.uint8)
        rgb[self.mask > 0] = colour
        return rgb


def detection_preview(detector, frame_set) -> list[ViewPreview]:
    """What the filter chain makes of one frame, per view (the project dialog's preview).

    Parameters
    ----------
    detector : videotrack.detect.FrameDetector
    frame_set : tuple of ndarray
        One frame per video (:meth:`videotrack.video.VideoSet.read`).

    Returns
    -------
    list of ViewPreview
        Per view: the view image, the mask (fields of de-interlaced video are stretched back
        to full height) and the centroids of the first field.
    """
    _, points, _ = detector(frame_set)[0]
    out = []
    for plane, chain, pts in zip(detector.planes[0], detector.filters[0], points, strict=True):
        frame = frame_set[plane.view.video]
        mask, _ = chain.run(plane.extract(frame))
        h = plane.view.size[1]
        if mask.shape[0] != h:  # one field: repeat its rows
            mask = np.repeat(mask, -(-h // mask.shape[0]), axis=0)[:h]
        out.append(ViewPreview(np.ascontiguousarray(plane.view.cut(frame)),
                               np.ascontiguousarray(plane.view.flip_image(mask)), pts))
    return out


def relative_path(path, base) -> str:
    """``path`` relative to the folder ``base`` when below it, else absolute (POSIX form)."""
    from pathlib import Path

    p, b = Path(path).absolute(), Path(base).absolute()
    try:
        return p.relative_to(b).as_posix()
    except ValueError:
        return p.as_posix()


def body_tree(body: Body) -> list[tuple]:
    """Rows of the chain editor's tree, depth first: ``(depth, kind, name, owner)`` with kind
    one of chain, joint, axis, segment, marker; ``owner`` is the axis' posture index, else
    None."""
    rows: list[tuple] = []
    index = {id(j): 3 * k for k, (_, j, _, _) in enumerate(body.joints())}

    def joint(j: Joint, depth: int) -> None:
        rows.append((depth, "joint", j.name, None))
        for e, a in enumerate(j.axes):
            rows.append((depth + 1, "axis", a.name, index[id(j)] + e))
        for s in j.segments:
            rows.append((depth + 1, "segment", s.name, None))
            for m in s.markers:
                rows.append((depth + 2, "marker", m.name, None))
            for c in s.joints:
                joint(c, depth + 2)

    for chain in body.chains:
        rows.append((0, "chain", chain.name, None))
        joint(chain.root_joint, 1)
    return rows


def find_element(body: Body, kind: str, name: str) -> Chain | Joint | Segment | Marker | None:
    """The chain, joint, segment or marker named ``name``."""
    if kind == "chain":
        return next((c for c in body.chains if c.name == name), None)
    if kind == "joint":
        return next((j for _, j, _, _ in body.joints() if j.name == name), None)
    if kind == "segment":
        return next((s for _, s in body.segments() if s.name == name), None)
    if kind == "marker":
        return next((m for _, _, m in body.markers() if m.name == name), None)
    raise ValueError(f"unknown element kind {kind!r}")
