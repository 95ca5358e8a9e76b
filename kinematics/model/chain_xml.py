"""Chain files: a :class:`~kinematics.model.Body` as XML (format in ``docs/formats.md``).

Loading goes file → hardened parse and XSD validation (:mod:`kinematics.model.safe_xml`) → records →
:func:`~kinematics.model.validate_body`. Every error names the file, the line and the element,
also for the semantic rules of ``validate_body``, whose field (``"joint 'J1' axis 'beta'"``) is
mapped back to the line of that element.

Axes without an entry in the ``<histograms>`` section get the paper's initial histogram:
uniform over [min, max], or a single bin at the locked value. Saving writes that section only
for histograms that differ from this default, so a freshly loaded chain saves back without one.
"""

from __future__ import annotations

import os
from collections import defaultdict
from dataclasses import replace

from kinematics.errors import KinematicsError
from kinematics.fileio import atomic_write_text
from kinematics.model import (
    Axis,
    Body,
    Chain,
    Joint,
    Marker,
    Root,
    Segment,
    check_histogram_range,
    safe_xml,
    validate_body,
)
from kinematics.model.histogram_xml import axis_keys, histogram_lines, key_text, read_histograms
from kinematics.model.histograms import Histogram

ROOT_TAG = "body"
FORMAT_VERSION = "1"
_ZERO = (0.0, 0.0, 0.0)


def default_histogram(min_deg: float, max_deg: float, locked_deg: float | None) -> Histogram:
    """The histogram an axis starts with (Sect. 2.2): uniform over its range, or the single
    bin of its locked value."""
    if locked_deg is not None:
        return Histogram.locked(locked_deg)
    return Histogram.uniform(min_deg, max_deg)


# -- loading --------------------------------------------------------------------------------
def load_body(path: str | os.PathLike) -> Body:
    """Load and validate a chain file.

    Raises
    ------
    KinematicsError
        For anything wrong with the file, as ``path:line: element: message``.
    """
    root = safe_xml.read_document(path, ROOT_TAG)
    return _body_from_element(root, os.fspath(path))


def loads_body(text: str | bytes, source: str = "<string>") -> Body:
    """:func:`load_body` from text; ``source`` names it in errors."""
    root = safe_xml.parse_document(text, source, ROOT_TAG)
    return _body_from_element(root, source)


def _body_from_element(root: safe_xml.Element, source: str) -> Body:
    lines = _Lines()
    try:
        body = _body(root, lines)
        try:
            validate_body(body)
        except KinematicsError as err:
            raise err.located(line=lines.line_of(err)) from None
        section = root.find("histograms")
        if section is not None:
            body = _with_histograms(body, section)
    except KinematicsError as err:
        raise err.located(file=source) from None
    return body


class _Lines:
    """Source lines of the named elements, keyed like ``validate_body``'s error fields."""

    def __init__(self) -> None:
        self._lines: dict[str, list[int]] = defaultdict(list)

    def add(self, field: str, elem: safe_xml.Element) -> None:
        self._lines[field].append(elem.sourceline)

    def line_of(self, err: KinematicsError) -> int | None:
        """Line of the element ``err.field`` names (``"joint 'J1' orientation"`` → the joint).

        For a duplicate name it is the second occurrence, also when the field names the
        parent (``duplicate axis names`` is reported on the joint).
        """
        field = err.field or ""
        inside = {k: sorted(v) for k, v in self._lines.items()
                  if k == field or k.startswith(field + " ")}
        if err.message.startswith("duplicate"):
            seconds = [v[1] for v in inside.values() if len(v) > 1]
            if seconds:
                return min(seconds)
        owners = [k for k in self._lines if field == k or field.startswith(k + " ")]
        if owners:
            return min(self._lines[max(owners, key=len)])
        return min(self._lines["body"], default=None)


def _body(elem: safe_xml.Element, lines: _Lines) -> Body:
    name = elem.get("name")
    for field in ("body", f"body '{name}'", "units"):
        lines.add(field, elem)
    chains = tuple(_chain(c, lines) for c in elem.iterchildren("chain"))
    description = elem.findtext("description") or ""
    return Body(name, chains, elem.get("units"), description.strip())


def _chain(elem: safe_xml.Element, lines: _Lines) -> Chain:
    name = elem.get("name")
    lines.add(f"chain '{name}'", elem)
    root_elem = elem.find("root")
    root = Root()
    if root_elem is not None:
        where = f"chain '{name}' root"
        lines.add(where, root_elem)
        mode, marker = root_elem.get("mode"), root_elem.get("marker")
        if mode == "marker" and marker is None:
            raise KinematicsError("mode 'marker' needs the attribute 'marker'",
                                  line=root_elem.sourceline, field=where)
        root = Root(mode, safe_xml.get_vec3(root_elem, "position", where), marker,
                    safe_xml.get_float(root_elem, "translation_window", where),
                    safe_xml.get_float(root_elem, "rotation_window_deg", where))
    return Chain(name, _joint(elem.find("joint"), lines), root)


def _joint(elem: safe_xml.Element, lines: _Lines) -> Joint:
    name = elem.get("name")
    where = f"joint '{name}'"
    lines.add(where, elem)
    axes = tuple(_axis(a, where, lines) for a in elem.iterchildren("axis"))
    segments = tuple(_segment(s, lines) for s in elem.iterchildren("segment"))
    return Joint(
        name, axes,
        orientation_deg=safe_xml.get_vec3(elem, "orientation", where),
        translation=safe_xml.get_vec3(elem, "translation", where),
        segments=segments,
    )


def _axis(elem: safe_xml.Element, joint_where: str, lines: _Lines) -> Axis:
    name = elem.get("name")
    where = f"{joint_where} axis '{name}'"
    lines.add(where, elem)
    lo, hi, locked = (safe_xml.get_float(elem, k, where) for k in ("min", "max", "locked"))
    try:
        if (lo is None) != (hi is None):
            raise KinematicsError("give both min and max, or neither for a locked axis")
        if lo is None:
            if locked is None:
                raise KinematicsError("an axis needs min and max, or locked")
            lo = hi = locked
        return Axis(name, elem.get("rot"), lo, hi, default_histogram(lo, hi, locked), locked)
    except KinematicsError as err:
        raise err.located(line=elem.sourceline, field=where) from None


def _segment(elem: safe_xml.Element, lines: _Lines) -> Segment:
    name = elem.get("name")
    where = f"segment '{name}'"
    lines.add(where, elem)
    markers = []
    for m in elem.iterchildren("marker"):
        m_where = f"marker '{m.get('name')}'"
        lines.add(m_where, m)
        markers.append(Marker(m.get("name"), safe_xml.get_vec3(m, "offset", m_where)))
    return Segment(
        name,
        safe_xml.get_float(elem, "length", where),
        rotation_deg=safe_xml.get_vec3(elem, "rotation", where),
        markers=tuple(markers),
        joints=tuple(_joint(j, lines) for j in elem.iterchildren("joint")),
    )


def _with_histograms(body: Body, section: safe_xml.Element) -> Body:
    entries = read_histograms(section.iterchildren("histogram"))
    axes = axis_keys(body)
    for key, (_, line) in entries.items():
        if key not in axes:
            raise KinematicsError(f"not an axis of body '{body.name}'", line=line,
                                  field=f"histogram {key_text(key)}")
    body = body.with_histograms({f"{j}.{a}": h for (_, j, a), (h, _) in entries.items()})
    free_roots = {c.root_joint.name for c in body.chains if c.root.free}
    for key, (hist, line) in entries.items():
        if key[1] not in free_roots:
            try:
                check_histogram_range(replace(axes[key], histogram=hist),
                                      f"histogram {key_text(key)}")
            except KinematicsError as err:
                raise err.located(line=line) from None
    return body


# -- saving ---------------------------------------------------------------------------------
def body_to_string(body: Body, include_histograms: bool = True) -> str:
    """The body as chain-file XML: pretty-printed, numbers short but exact.

    With ``include_histograms``, a ``<histograms>`` section holds every histogram that differs
    from its axis's default (:func:`default_histogram`).
    """
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        safe_xml.tag(ROOT_TAG, {"name": body.name, "units": body.units,
                                "format": FORMAT_VERSION}, 0, close=False),
    ]
    if body.description:
        out.append(f"  <description>{safe_xml.escape_text(body.description)}</description>")
    for chain in body.chains:
        root = chain.root
        out.append(safe_xml.tag("chain", {"name": chain.name}, 1, close=False))
        out.append(safe_xml.tag("root", {
            "mode": root.mode, "position": safe_xml.format_vec(root.position),
            "marker": root.marker,
            "translation_window": _opt_number(root.translation_window),
            "rotation_window_deg": _opt_number(root.rotation_window_deg)}, 2))
        _write_joint(chain.root_joint, 2, out)
        out.append("  </chain>")
    learned = [
        (key, axis.histogram) for key, axis in axis_keys(body).items()
        if axis.histogram != default_histogram(axis.min_deg, axis.max_deg, axis.locked_deg)
    ]
    if include_histograms and learned:
        out.append("  <histograms>")
        for key, hist in learned:
            out.extend(histogram_lines(key, hist, 2))
        out.append("  </histograms>")
    out.append(f"</{ROOT_TAG}>")
    return "\n".join(out) + "\n"


def _nonzero_vec(v) -> str | None:
    """A vector attribute, left out when it is the default (0, 0, 0)."""
    return None if tuple(v) == _ZERO else safe_xml.format_vec(v)


def _write_joint(joint: Joint, indent: int, out: list[str]) -> None:
    out.append(safe_xml.tag("joint", {
        "name": joint.name,
        "orientation": _nonzero_vec(joint.orientation_deg),
        "translation": _nonzero_vec(joint.translation),
    }, indent, close=False))
    for a in joint.axes:
        fmt = safe_xml.format_number
        only_locked = a.locked and a.min_deg == a.max_deg == a.locked_deg
        out.append(safe_xml.tag("axis", {
            "rot": a.rot, "name": a.name,
            "min": None if only_locked else fmt(a.min_deg),
            "max": None if only_locked else fmt(a.max_deg),
            "locked": fmt(a.locked_deg) if a.locked else None,
        }, indent + 1))
    for seg in joint.segments:
        out.append(safe_xml.tag("segment", {
            "name": seg.name, "length": safe_xml.format_number(seg.length),
            "rotation": _nonzero_vec(seg.rotation_deg),
        }, indent + 1, close=not (seg.markers or seg.joints)))
        for m in seg.markers:
            out.append(safe_xml.tag("marker", {
                "name": m.name, "offset": safe_xml.format_vec(m.offset)}, indent + 2))
        for child in seg.joints:
            _write_joint(child, indent + 2, out)
        if seg.markers or seg.joints:
            out.append("  " * (indent + 1) + "</segment>")
    out.append("  " * indent + "</joint>")


def save_body(path: str | os.PathLike, body: Body, include_histograms: bool = True) -> None:
    """Write ``body`` to ``path`` atomically (temporary file, then ``os.replace``).

    The text is loaded back before writing, so a body that cannot be stored (a name with a
    space, an invalid range …) raises :class:`KinematicsError` and leaves the file untouched.
    """
    text = body_to_string(body, include_histograms)
    try:
        loads_body(text)
    except KinematicsError as err:
        where = f"{err.field}: " if err.field else ""
        raise KinematicsError(f"cannot save body: {where}{err.message}", file=path) from None
    atomic_write_text(path, text)


def _opt_number(value: float | None) -> str | None:
    return None if value is None else safe_xml.format_number(value)
