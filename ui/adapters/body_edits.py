"""Body edits of the chain editor and of manual corrections: joints, segments, markers,
roots and axes changed, the axes a marker hangs on, a marker drag solved, and the chain's
tree (no Qt)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from kinematics.errors import KinematicsError
from kinematics.model import Axis, Body, Chain, Joint, Marker, Segment
from kinematics.model.chain_xml import default_histogram
from kinematics.model.fk import forward_kinematics


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
    :func:`kinematics.fit.placement.root_windows`).

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
    from kinematics.fit.placement import root_windows

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
    bin of the locked value; :func:`kinematics.model.chain_xml.default_histogram`), because a
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
