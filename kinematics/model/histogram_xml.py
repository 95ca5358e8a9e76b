"""Joint-angle histogram archives (paper Sect. 2.2 and Discussion): XML I/O, merge, Eq. 4 update.

An archive maps ``(chain, joint, axis)`` names to :class:`~kinematics.model.histograms.Histogram`.
It is stored standalone as ``<histogram-archive>`` or inside a chain file's
``<body><histograms>`` section, with the same ``<histogram>`` element (see
``docs/formats.md``)::

    <histogram chain="hindleg" joint="J0" axis="phi" trials="12">
      <run from="-180" to="-140" value="0.01"/>
      <run from="120" to="180" value="0.01"/>
    </histogram>

Each ``<run>`` sets the bins between two bin edges (degrees, ``[from, to)``) to one value;
zero bins are left out. Values are written with ``repr``, so archives round-trip bit-exactly,
and one line per run keeps them readable in a diff.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from kinematics.errors import KinematicsError
from kinematics.fileio import atomic_write_text
from kinematics.model import Axis, Body, check_histogram_range, safe_xml
from kinematics.model.histograms import MAX_BIN_VALUE, N_BINS_DEFAULT, Histogram, merge_histograms

Key = tuple[str, str, str]
"""``(chain, joint, axis)`` names of one axis."""

ROOT_TAG = "histogram-archive"
FORMAT_VERSION = "1"


@dataclass(frozen=True)
class HistogramArchive(Mapping):
    """Histograms keyed by ``(chain, joint, axis)``, in file order, plus the body they belong
    to (informative: archives may be applied to any body with matching axis names) and the
    file they were read from (``source``, named in errors; not compared)."""

    histograms: Mapping[Key, Histogram]
    body: str | None = None
    description: str | None = None
    source: str | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        items = dict(self.histograms)
        for key, hist in items.items():
            if not (isinstance(key, tuple) and len(key) == 3
                    and all(isinstance(k, str) for k in key)):
                raise KinematicsError(f"archive keys are (chain, joint, axis) names, got {key!r}")
            if not isinstance(hist, Histogram):
                raise KinematicsError(f"{key_text(key)}: not a Histogram")
        object.__setattr__(self, "histograms", items)

    def __getitem__(self, key: Key) -> Histogram:
        return self.histograms[key]

    def __iter__(self) -> Iterator[Key]:
        return iter(self.histograms)

    def __len__(self) -> int:
        return len(self.histograms)

    __hash__ = None  # holds arrays; compare by value only


def key_text(key: Key) -> str:
    """``chain 'c' joint 'j' axis 'a'``, how errors name an archive entry."""
    return "chain '{}' joint '{}' axis '{}'".format(*key)


def axis_keys(body: Body) -> dict[Key, Axis]:
    """Every axis of ``body`` by its archive key, in posture-vector order."""
    return {(r.chain, r.joint, r.axis.name): r.axis for r in body.axis_refs()}


# -- body <-> archive -------------------------------------------------------------------------
def archive_from_body(body: Body) -> HistogramArchive:
    """The histograms of every axis of ``body`` (locked axes included), in posture order."""
    return HistogramArchive(
        {key: axis.histogram for key, axis in axis_keys(body).items()}, body=body.name
    )


def apply_archive(body: Body, archive: Mapping[Key, Histogram]) -> Body:
    """A copy of ``body`` whose axes carry the archive's histograms.

    Axes the archive does not name keep theirs. Raises :class:`KinematicsError` for an entry
    that names no axis of the body, whose bin count differs from the axis's histogram, or
    that lies entirely outside the range of a free axis.
    """
    try:
        _check_applicable(body, archive)
    except KinematicsError as err:
        raise err.located(file=getattr(archive, "source", None)) from None
    return body.with_histograms({f"{j}.{a}": h for (_, j, a), h in archive.items()})


def _check_applicable(body: Body, archive: Mapping[Key, Histogram]) -> None:
    axes = axis_keys(body)
    free_roots = {(c.name, c.root_joint.name) for c in body.chains if c.root.free}
    for key, hist in archive.items():
        axis = axes.get(key)
        if axis is None:
            raise KinematicsError(f"not an axis of body '{body.name}'", field=key_text(key))
        if hist.n_bins != axis.histogram.n_bins:
            raise KinematicsError(
                f"histogram has {hist.n_bins} bins, the body's has {axis.histogram.n_bins}",
                field=key_text(key),
            )
        if key[:2] not in free_roots:
            check_histogram_range(replace(axis, histogram=hist), key_text(key))


def update_archive(
    archive: HistogramArchive, body: Body, angles_deg
) -> HistogramArchive:
    """Learn from fitted postures: Eq. 4 applied per free axis for every frame.

    Parameters
    ----------
    archive : HistogramArchive
        The histograms to update; a free axis it lacks starts from the body's histogram.
    body : Body
        Defines the posture-vector layout and which axes are locked (those stay unchanged).
    angles_deg : array_like, shape (n_frames, n_axes)
        Fitted postures in :meth:`Body.axis_refs` order, degrees; NaN entries (frames that
        were not fitted) are skipped. A single posture of shape (n_axes,) is one frame.

    Returns
    -------
    HistogramArchive
        A new archive; each updated histogram's trial count grows by the frames it saw.
    """
    angles = np.atleast_2d(np.asarray(angles_deg, dtype=float))
    if angles.ndim != 2 or angles.shape[1] != body.n_axes:
        raise KinematicsError(
            f"angles must have shape (n_frames, {body.n_axes}), got {np.shape(angles_deg)}"
        )
    out = dict(archive.histograms)
    for ref in body.axis_refs():
        if ref.axis.locked:
            continue
        key = (ref.chain, ref.joint, ref.axis.name)
        out[key] = out.get(key, ref.axis.histogram).updated(angles[:, ref.index])
    return replace(archive, histograms=out, body=archive.body or body.name, source=None)


def merge_archives(archives: Sequence[HistogramArchive]) -> HistogramArchive:
    """Combine archives of several experiments: per axis, the histograms weighted by their
    trial counts N (:func:`~kinematics.model.histograms.merge_histograms`).

    An axis found in only some archives is merged from those; an archive that shares no
    chain with the first is refused (archives of different chains: their union would be a
    body no experiment saw). The body name is kept when all archives that name one agree.
    """
    if not archives:
        raise KinematicsError("no archives to merge")
    first = {k[0] for k in archives[0]}
    for a in archives[1:]:
        chains = {k[0] for k in a}
        if chains and first and not chains & first:
            raise KinematicsError(
                f"holds chains {sorted(chains)}, the first archive {sorted(first)}: archives of "
                "different chains cannot be merged", file=a.source)
    keys = list(dict.fromkeys(k for a in archives for k in a))
    merged = {}
    for key in keys:
        try:
            merged[key] = merge_histograms([a[key] for a in archives if key in a])
        except KinematicsError as err:
            raise err.located(field=key_text(key)) from None
    names = {a.body for a in archives if a.body}
    return HistogramArchive(merged, body=names.pop() if len(names) == 1 else None)


# -- XML ------------------------------------------------------------------------------------
def load_archive(path: str | os.PathLike) -> HistogramArchive:
    """Read a ``<histogram-archive>`` file (validated against the package schema)."""
    root = safe_xml.read_document(path, ROOT_TAG)
    return _archive_from_element(root, os.fspath(path))


def loads_archive(text: str | bytes, source: str = "<string>") -> HistogramArchive:
    """:func:`load_archive` from text; ``source`` names it in errors."""
    root = safe_xml.parse_document(text, source, ROOT_TAG)
    return _archive_from_element(root, source)


def _archive_from_element(root: safe_xml.Element, source: str) -> HistogramArchive:
    try:
        entries = read_histograms(root.iterchildren("histogram"))
    except KinematicsError as err:
        raise err.located(file=source) from None
    desc = root.find("description")
    return HistogramArchive(
        {key: hist for key, (hist, _) in entries.items()},
        body=root.get("body"),
        description=None if desc is None else (desc.text or ""),
        source=source,
    )


def read_histograms(elements: Iterable[safe_xml.Element]) -> dict[Key, tuple[Histogram, int]]:
    """Parse ``<histogram>`` elements into ``{key: (histogram, line)}``; duplicate keys and
    malformed runs raise :class:`KinematicsError` with the line."""
    out: dict[Key, tuple[Histogram, int]] = {}
    for elem in elements:
        key = (elem.get("chain"), elem.get("joint"), elem.get("axis"))
        where = f"histogram {key_text(key)}"
        if key in out:
            raise KinematicsError(
                f"duplicate histogram (first on line {out[key][1]})",
                line=elem.sourceline, field=where,
            )
        out[key] = (_read_histogram(elem, where), elem.sourceline)
    return out


def _read_histogram(elem: safe_xml.Element, where: str) -> Histogram:
    n_bins = safe_xml.get_int(elem, "bins", where)
    trials = safe_xml.get_int(elem, "trials", where)
    values = np.zeros(n_bins)
    covered = np.zeros(n_bins, dtype=bool)
    for run in elem.iterchildren("run"):
        try:
            lo = _edge_index(safe_xml.get_float(run, "from", where), n_bins)
            hi = _edge_index(safe_xml.get_float(run, "to", where), n_bins)
            value = safe_xml.get_float(run, "value", where)
            if lo >= hi:
                raise KinematicsError("run needs from < to")
            if value < 0:
                raise KinematicsError(f"run value must be >= 0, got {value!r}")
            if value > MAX_BIN_VALUE:
                raise KinematicsError(
                    f"run value {value!r} is too large (at most {MAX_BIN_VALUE:g}; values are "
                    "normalised to sum 1 on loading, so probabilities or counts will do)")
            if covered[lo:hi].any():
                raise KinematicsError("run overlaps another run")
        except KinematicsError as err:
            raise err.located(line=run.sourceline, field=where) from None
        values[lo:hi] = value
        covered[lo:hi] = True
    try:
        return Histogram(values, trials)
    except KinematicsError as err:
        raise err.located(line=elem.sourceline, field=where) from None


def _edge_index(angle_deg: float, n_bins: int) -> int:
    """Index k of the bin edge ``-180 + k·360/n_bins`` at ``angle_deg``."""
    k = (angle_deg + 180.0) * n_bins / 360.0
    index = round(k) if -1.0 <= k <= n_bins + 1.0 else -1  # (1e308: no integer)
    if abs(k - index) > 1e-6 or not 0 <= index <= n_bins:
        raise KinematicsError(
            f"{angle_deg!r} is not a bin edge (edges lie at -180 + k·{360.0 / n_bins:g} "
            "degrees, up to 180)"
        )
    return index


def histogram_lines(key: Key, hist: Histogram, indent: int) -> list[str]:
    """The ``<histogram>`` element of one axis as text lines (one ``<run>`` per run of equal,
    non-zero consecutive bins)."""
    chain, joint, axis = key
    attrs = {
        "chain": chain, "joint": joint, "axis": axis,
        "bins": None if hist.n_bins == N_BINS_DEFAULT else str(hist.n_bins),
        "trials": str(hist.n_trials),
    }
    values = hist.values
    edges = np.flatnonzero(np.diff(values)) + 1
    starts, ends = np.r_[0, edges], np.r_[edges, hist.n_bins]
    lines = [safe_xml.tag("histogram", attrs, indent, close=False)]
    for lo, hi in zip(starts, ends, strict=True):
        if values[lo] != 0:
            lines.append(safe_xml.tag("run", {
                "from": safe_xml.format_number(lo * 360.0 / hist.n_bins - 180.0),
                "to": safe_xml.format_number(hi * 360.0 / hist.n_bins - 180.0),
                "value": safe_xml.format_number(values[lo]),
            }, indent + 1))
    lines.append("  " * indent + "</histogram>")
    return lines


def archive_to_string(archive: HistogramArchive) -> str:
    """The archive as ``<histogram-archive>`` XML text."""
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        safe_xml.tag(ROOT_TAG, {"format": FORMAT_VERSION, "body": archive.body}, 0, close=False),
    ]
    if archive.description is not None:
        lines.append(f"  <description>{safe_xml.escape_text(archive.description)}</description>")
    for key, hist in archive.items():
        lines.extend(histogram_lines(key, hist, 1))
    lines.append(f"</{ROOT_TAG}>")
    return "\n".join(lines) + "\n"


def save_archive(path: str | os.PathLike, archive: HistogramArchive) -> None:
    """Write the archive to ``path`` atomically (temporary file, then ``os.replace``)."""
    atomic_write_text(path, archive_to_string(archive))
