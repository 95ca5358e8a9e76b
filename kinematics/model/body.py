"""The kinematic body model (paper Sect. 2.1, Fig. 2) as small frozen records.

A :class:`Body` holds one or more :class:`Chain`. A chain starts at a root :class:`Joint`;
a joint carries :class:`Segment` children, and a segment carries :class:`Marker` and further
joints at its distal end. Each joint has three rotation axes, stored in the order of Eq. 1
(``y, x, z``; ``R = Ry·Rx·Rz``), each with a user name, a range, an optional locked value
and a :class:`~kinematics.model.histograms.Histogram`.

The posture of a body is one flat vector of angles (degrees at the API, radians inside
kernels), in depth-first joint order and ``y, x, z`` within a joint; its entries are named
``joint.axis`` (e.g. ``J0.phi``), which is also the column name in results files.

Transforms (Eq. 1 and 2), written once in :mod:`kinematics.model.fk`:

* root joint frame ``J0 = T(root) · R0 · R0d · T0``
* joint under segment ``S`` of joint ``P``: ``Jn = P · S · Rn · Rnd · Tn``
* segment ``S = T^s(length along local x) · R^s``
* marker ``M = J · S · m`` — marker offsets are in the frame at the segment's distal end,
  so ``(0, 0, 0)`` is the distal end and ``(-length, 0, 0)`` the proximal joint (when R^s = I).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from kinematics.errors import KinematicsError
from kinematics.model.histograms import Histogram
from kinematics.model.rotations import AXIS_ORDER

UNITS = ("px", "mm")
ROOT_MODES = ("fixed", "marker", "free")
Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Axis:
    """One rotational degree of freedom of a joint.

    ``rot`` is which elementary rotation it drives (``"y"``, ``"x"`` or ``"z"``); ``min_deg``
    and ``max_deg`` its physiological range; ``locked_deg`` a fixed value (hinge joints lock
    two axes) or None; ``histogram`` its angle distribution (constraint and prior).
    """

    name: str
    rot: str
    min_deg: float
    max_deg: float
    histogram: Histogram
    locked_deg: float | None = None

    @property
    def locked(self) -> bool:
        return self.locked_deg is not None

    @classmethod
    def free(cls, name: str, rot: str, min_deg: float, max_deg: float) -> Axis:
        """A free axis with the paper's initial uniform histogram over its range."""
        return cls(name, rot, float(min_deg), float(max_deg), Histogram.uniform(min_deg, max_deg))

    @classmethod
    def fixed(cls, name: str, rot: str, value_deg: float = 0.0) -> Axis:
        """A locked axis (single histogram bin), as the paper's hinge joints."""
        v = float(value_deg)
        return cls(name, rot, v, v, Histogram.locked(v), locked_deg=v)


@dataclass(frozen=True)
class Marker:
    """A marker at ``offset`` in the distal frame of its segment (Eq. 2)."""

    name: str
    offset: Vec3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Segment:
    """A rigid segment: translation ``length`` along the joint's x axis, then ``rotation_deg``
    (R^s, Euler y, x, z in degrees); carries markers and the joints at its distal end."""

    name: str
    length: float
    rotation_deg: Vec3 = (0.0, 0.0, 0.0)
    markers: tuple[Marker, ...] = ()
    joints: tuple[Joint, ...] = ()


@dataclass(frozen=True)
class Joint:
    """A joint: three axes (order y, x, z), default orientation R^d (Euler y, x, z in degrees),
    translation T applied after the rotations (Eq. 1), and its child segments."""

    name: str
    axes: tuple[Axis, Axis, Axis]
    orientation_deg: Vec3 = (0.0, 0.0, 0.0)
    translation: Vec3 = (0.0, 0.0, 0.0)
    segments: tuple[Segment, ...] = ()


@dataclass(frozen=True)
class Root:
    """How the chain's root is placed.

    ``fixed``: at ``position``. ``marker``: following the detected root ``marker`` (tracked
    by nearest neighbour from ``position`` in the first frame). ``free``: a freely moving
    body; the root joint's position and orientation (its three axes) are fitted per frame,
    seeded by registering the markers of the root joint's own segments to points
    triangulated from the views (:mod:`kinematics.fit.placement`). ``translation_window``
    (length units) and ``rotation_window_deg`` bound the search around that seed; None
    picks defaults from the body's size (:func:`kinematics.fit.placement.root_windows`).
    ``position`` is then only a hint used when the root cannot be registered.
    """

    mode: str = "fixed"
    position: Vec3 = (0.0, 0.0, 0.0)
    marker: str | None = None
    translation_window: float | None = None
    rotation_window_deg: float | None = None

    @property
    def free(self) -> bool:
        return self.mode == "free"


@dataclass(frozen=True)
class Chain:
    name: str
    root_joint: Joint
    root: Root = field(default_factory=Root)


@dataclass(frozen=True)
class AxisRef:
    """Where an axis sits in the flat posture vector."""

    index: int
    chain: str
    joint: str
    axis: Axis

    @property
    def label(self) -> str:
        return f"{self.joint}.{self.axis.name}"


@dataclass(frozen=True)
class Body:
    """A body made of kinematic chains; ``units`` are the length units of the file and
    ``description`` free text (provenance, licence notes) kept through load and save."""

    name: str
    chains: tuple[Chain, ...]
    units: str = "px"
    description: str = ""

    # -- traversal --------------------------------------------------------------------
    def joints(self) -> Iterator[tuple[Chain, Joint, Joint | None, Segment | None]]:
        """Depth-first (chain, joint, parent joint, parent segment); parents before children."""
        for chain in self.chains:
            stack: list[tuple[Joint, Joint | None, Segment | None]] = [
                (chain.root_joint, None, None)
            ]
            while stack:
                joint, parent, seg = stack.pop()
                yield chain, joint, parent, seg
                for s in reversed(joint.segments):
                    stack.extend((j, joint, s) for j in reversed(s.joints))

    def segments(self) -> Iterator[tuple[Joint, Segment]]:
        """Every (owning joint, segment) in joint order."""
        for _, joint, _, _ in self.joints():
            for seg in joint.segments:
                yield joint, seg

    def markers(self) -> Iterator[tuple[Joint, Segment, Marker]]:
        """Every (owning joint, segment, marker) in joint order."""
        for joint, seg in self.segments():
            for m in seg.markers:
                yield joint, seg, m

    def axis_refs(self) -> list[AxisRef]:
        """All axes in posture-vector order."""
        refs = []
        for chain, joint, _, _ in self.joints():
            for axis in joint.axes:
                refs.append(AxisRef(len(refs), chain.name, joint.name, axis))
        return refs

    # -- posture-vector helpers -------------------------------------------------------
    @property
    def n_axes(self) -> int:
        return 3 * sum(1 for _ in self.joints())

    @property
    def axis_labels(self) -> list[str]:
        return [r.label for r in self.axis_refs()]

    @property
    def marker_names(self) -> list[str]:
        return [m.name for _, _, m in self.markers()]

    @property
    def joint_names(self) -> list[str]:
        return [j.name for _, j, _, _ in self.joints()]

    def locked_mask(self) -> np.ndarray:
        return np.array([r.axis.locked for r in self.axis_refs()], dtype=bool)

    def ranges_deg(self) -> np.ndarray:
        """(n_axes, 2) array of (min, max)."""
        return np.array([(r.axis.min_deg, r.axis.max_deg) for r in self.axis_refs()])

    def histograms(self) -> list[Histogram]:
        return [r.axis.histogram for r in self.axis_refs()]

    def mean_posture_deg(self) -> np.ndarray:
        """Start posture of Sect. 3.1: histogram means, locked axes at their value."""
        out = []
        for r in self.axis_refs():
            a = r.axis
            out.append(a.locked_deg if a.locked else _mean_in_range(a))
        return np.array(out)

    def root_positions(self) -> np.ndarray:
        """(n_chains, 3) configured root positions."""
        return np.array([c.root.position for c in self.chains], dtype=float)

    # -- editing ----------------------------------------------------------------------
    def with_histograms(self, histograms: dict[str, Histogram]) -> Body:
        """A copy with the histograms of the named axes (``joint.axis`` labels) replaced."""
        def edit_joint(j: Joint) -> Joint:
            axes = tuple(
                replace(a, histogram=histograms.get(f"{j.name}.{a.name}", a.histogram))
                for a in j.axes
            )
            segs = tuple(replace(s, joints=tuple(edit_joint(c) for c in s.joints))
                         for s in j.segments)
            return replace(j, axes=axes, segments=segs)

        unknown = set(histograms) - set(self.axis_labels)
        if unknown:
            raise KinematicsError(f"no such axis in body '{self.name}': {sorted(unknown)[0]}")
        chains = tuple(replace(c, root_joint=edit_joint(c.root_joint)) for c in self.chains)
        return replace(self, chains=chains)

    def validate(self) -> None:
        """Check the semantic rules the XML schema cannot express; raise KinematicsError."""
        validate_body(self)


def _mean_in_range(axis: Axis) -> float:
    """Histogram mean, unwrapped to lie near the axis range (ranges may exceed ±180°)."""
    m = axis.histogram.mean_deg()
    centre = 0.5 * (axis.min_deg + axis.max_deg)
    return m + 360.0 * np.round((centre - m) / 360.0)


#: The longest segment a body may have (a human in nanometres is 2e9).
MAX_LENGTH = 1e12


def validate_body(body: Body) -> None:
    """Raise :class:`KinematicsError` naming the element for the first rule broken.

    Rules: units known; names non-empty and unique per kind (joint names are unique in the
    body because posture columns are ``joint.axis``); no marker named like a joint and no
    axis named x, y or z (3D point columns are ``name.x``); each joint has one axis per rotation
    y, x, z with unique names; numbers finite; min <= max; locked values inside the range;
    segment lengths >= 0; a ``marker`` root names a marker of its chain; the histogram of
    every axis the annealing moves has mass inside the axis's range
    (:func:`check_histogram_range`).
    """
    if body.units not in UNITS:
        raise KinematicsError(f"units must be one of {UNITS}, got '{body.units}'", field="units")
    if not body.chains:
        raise KinematicsError("body has no chain", field=f"body '{body.name}'")
    seen: dict[str, set[str]] = {"chain": set(), "joint": set(), "segment": set(), "marker": set()}

    def unique(kind: str, name: str) -> None:
        if not name or not name.strip():
            raise KinematicsError(f"{kind} without a name", field=kind)
        if name in seen[kind]:
            raise KinematicsError(f"duplicate {kind} name '{name}'", field=f"{kind} '{name}'")
        seen[kind].add(name)

    for chain in body.chains:
        unique("chain", chain.name)
    for chain, joint, parent, _ in body.joints():
        unique("joint", joint.name)
        where = f"joint '{joint.name}'"
        _check_vec(joint.orientation_deg, f"{where} orientation")
        _check_vec(joint.translation, f"{where} translation")
        if tuple(a.rot for a in joint.axes) != AXIS_ORDER:
            raise KinematicsError(
                "a joint needs exactly one axis each for rotations y, x, z", field=where
            )
        names = [a.name for a in joint.axes]
        if len(set(names)) != 3:
            raise KinematicsError(f"duplicate axis names {names}", field=where)
        for a in joint.axes:
            if a.name in AXIS_ORDER:
                raise KinematicsError(
                    f"axis name '{a.name}' would read like a 3D coordinate in results "
                    f"('{joint.name}.{a.name}'); name it e.g. 'r{a.name}'",
                    field=f"{where} axis '{a.name}'")
        for a in joint.axes:
            _check_axis(a, f"{where} axis '{a.name}'")
        # A free root's axes are searched around a seed within a window, not by histogram.
        if not (parent is None and chain.root.free):
            for a in joint.axes:
                check_histogram_range(a, f"{where} axis '{a.name}'")
        for seg in joint.segments:
            unique("segment", seg.name)
            sw = f"segment '{seg.name}'"
            if not np.isfinite(seg.length) or seg.length < 0:
                raise KinematicsError(f"length must be finite and >= 0, got {seg.length}",
                                      field=sw)
            if seg.length > MAX_LENGTH:  # a typo: the kinematics' squares would overflow
                raise KinematicsError(f"length {seg.length:g} is out of range (at most "
                                      f"{MAX_LENGTH:g})", field=sw)
            _check_vec(seg.rotation_deg, f"{sw} rotation")
            for m in seg.markers:
                unique("marker", m.name)
                _check_vec(m.offset, f"marker '{m.name}' offset")
    clash = seen["marker"] & seen["joint"]
    if clash:
        name = sorted(clash)[0]
        raise KinematicsError(f"marker '{name}' has the name of a joint; results name points "
                              "by these names, so they must differ", field=f"marker '{name}'")
    for chain in body.chains:
        root = chain.root
        where = f"chain '{chain.name}' root"
        if root.mode not in ROOT_MODES:
            raise KinematicsError(f"root mode must be one of {ROOT_MODES}", field=where)
        _check_vec(root.position, f"{where} position")
        if root.mode == "marker" or root.marker is not None:
            names = {m.name for _, _, m in Body(body.name, (chain,), body.units).markers()}
            if root.marker not in names:
                raise KinematicsError(
                    f"root marker '{root.marker}' is not a marker of the chain", field=where
                )
        for name, value in (("translation_window", root.translation_window),
                            ("rotation_window_deg", root.rotation_window_deg)):
            if value is not None and not (np.isfinite(value) and value > 0):
                raise KinematicsError(f"{name} must be a number > 0, got {value}",
                                      field=where)
        if root.free:
            locked = [a.name for a in chain.root_joint.axes if a.locked]
            if locked:
                raise KinematicsError(
                    f"a free root turns about all three axes of its joint "
                    f"'{chain.root_joint.name}', but '{locked[0]}' is locked; unlock it or "
                    "use mode 'fixed' or 'marker'", field=where)
            if not any(s.markers for s in chain.root_joint.segments):
                raise KinematicsError(
                    f"a free root needs markers on the segments of its joint "
                    f"'{chain.root_joint.name}' to place the body", field=where)


def check_histogram_range(axis: Axis, where: str) -> None:
    """Refuse a free axis whose histogram has no mass inside the axis's range: annealing only
    accepts angles in the range with a non-zero histogram bin, so every frame would fail.
    Locked axes are skipped (their histogram is never consulted)."""
    if axis.locked:
        return
    h = axis.histogram
    if h.mass_in_range(axis.min_deg, axis.max_deg) > 0:
        return
    lo, hi = h.support_deg()
    raise KinematicsError(
        f"histogram lies entirely outside the axis range [{axis.min_deg:g}, {axis.max_deg:g}]"
        f" deg (its non-zero bins cover [{lo:g}, {hi:g}]); no angle would be plausible and "
        "every frame would fail: learn it on this axis or widen the range", field=where)


def _check_vec(v, where: str) -> None:
    arr = np.asarray(v, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise KinematicsError(f"needs three finite numbers, got {v}", field=where)


def _check_axis(a: Axis, where: str) -> None:
    if a.rot not in AXIS_ORDER:
        raise KinematicsError(f"rotation must be one of {AXIS_ORDER}", field=where)
    if not (np.isfinite(a.min_deg) and np.isfinite(a.max_deg)):
        raise KinematicsError("range must be finite", field=where)
    if a.min_deg > a.max_deg:
        raise KinematicsError(f"min {a.min_deg:g} is greater than max {a.max_deg:g}", field=where)
    if a.max_deg - a.min_deg > 360.0:
        raise KinematicsError("range is wider than 360 degrees", field=where)
    if a.locked and not (np.isfinite(a.locked_deg)
                         and a.min_deg - 1e-9 <= a.locked_deg <= a.max_deg + 1e-9):
        raise KinematicsError(f"locked value {a.locked_deg:g} is outside the range", field=where)
