"""Results files: one CSV per video a person can open, plus a JSON sidecar.

The CSV has one row per analysed image (frame, or field when de-interlaced)::

    frame, video_frame, field, time, <joint>.<axis> ... (degrees), error, error.<view> ...,
    runs, iterations, matched, unexplained, worst_px, <joint>.<axis>.sd ..., status,
    <chain>.root.x/y/z ..., <marker>.x/y/z ..., <joint>.x/y/z ..., <marker>.res.<view> ...

``matched`` counts the marker images within ``claim_gate_px`` of a detection, ``unexplained``
the detections farther than that from every model marker, ``worst_px`` is the largest marker
residual: sort by them to find frames to look at. The ``.sd`` columns are each angle's
standard deviation in degrees given the noise model (how sure the fit is of it: about 95 %
of right frames lie within 2 sd of the truth), 0 for locked axes, empty where no noise
model was measured.

The ``.res.`` columns are per-marker residuals: how far, in pixels, each fitted model marker
is from the detection it matched (its nearest) in each view; empty where the view had no
detection. They show which marker of a frame is off (a swapped or missing marker).

``status`` is ``ok``, ``reanalysed``, ``ambiguous`` (another candidate posture far from this
one fits about as well, or the frame needs a look for another reason:
:class:`kinematics.fit.FrameResult`), ``failed``, ``no-detections`` or ``corrected``
(set by hand in the GUI). Empty cells are NaN. The sidecar ``<results>.json`` records the
seed, every fitting parameter, the chain, cameras and detections used (paths relative to
the results file's folder, and content hashes) so any run can be replayed and stale
results recognised, and the warnings of the run that made the results (``warnings``). Both
are written atomically.

With candidate postures (``[anneal] candidates`` > 1) a third file,
``<results stem>.candidates.csv``, holds every frame's distinct postures: ``frame, rank,
chosen, error, <joint>.<axis> ..., <chain>.root.x/y/z ...``, rank 0 the lowest E, ``chosen``
1 for the posture in the results. The path through time can be chosen again from it without
refitting (:func:`read_candidates`, :func:`kinematics.fit.temporal.choose_path`).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinematics.fileio import atomic_write_text
from kinematics.fit.result import TRUSTED, Status
from kinematics.model import Body
from kinematics.model.fk import forward_kinematics
from kinematics.model.packing import pack_body
from videotrack.errors import VideoTrackError
from videotrack.results.tables import format_cell

#: Every status a results file may hold (a fit's, and ``corrected`` by hand).
STATUSES = tuple(Status)
#: Suffix of the per-axis standard deviation columns (FrameResult.sd_deg).
SD_SUFFIX = ".sd"
#: Per-frame match counts (FrameResult.matched, .unexplained, .worst_px), between iterations
#: and status; files written before they existed lack them.
QUALITY_COLUMNS = ("matched", "unexplained", "worst_px")
RESULTS_FORMAT = 1


@dataclass(frozen=True, eq=False)
class Results:
    """Fitted postures of a video, with everything the CSV holds.

    Shapes: ``n`` rows, ``a`` axes, ``v`` views, ``c`` chains, ``m`` markers, ``j`` joints.
    """

    axis_labels: tuple[str, ...]
    view_names: tuple[str, ...]
    chain_names: tuple[str, ...]
    marker_names: tuple[str, ...]
    joint_names: tuple[str, ...]
    frames: np.ndarray  # (n,) record index in the detections
    video_frames: np.ndarray  # (n,) frame of the video
    fields: np.ndarray  # (n,) 0/1 field parity, -1 for whole frames
    times: np.ndarray  # (n,) seconds
    angles_deg: np.ndarray  # (n, a)
    error: np.ndarray  # (n,)
    error_per_view: np.ndarray  # (n, v)
    runs: np.ndarray  # (n,)
    iterations: np.ndarray  # (n,)
    status: tuple[str, ...]  # (n,)
    roots: np.ndarray  # (n, c, 3)
    markers: np.ndarray  # (n, m, 3)
    joints: np.ndarray  # (n, j, 3)
    residuals: np.ndarray | None = None  # (n, m, v) pixels, or None (older files)
    quality: np.ndarray | None = None  # (n, 3) matched, unexplained, worst_px; None: older
    sd: np.ndarray | None = None  # (n, a) degrees; None: no noise model, or an older file

    def __len__(self) -> int:
        return self.frames.size

    def ok_mask(self, ambiguous: bool = True) -> np.ndarray:
        """Rows whose fit met the error threshold (ok, re-analysed, corrected by hand and,
        unless ``ambiguous`` is False, ambiguous)."""
        good = TRUSTED | {Status.AMBIGUOUS} if ambiguous else TRUSTED
        return np.array([s in good for s in self.status], bool)

    @property
    def columns(self) -> list[str]:
        cols = ["frame", "video_frame", "field", "time", *self.axis_labels, "error"]
        cols += [f"error.{v}" for v in self.view_names]
        cols += ["runs", "iterations"]
        if self.quality is not None:
            cols += list(QUALITY_COLUMNS)
        if self.sd is not None:
            cols += [f"{a}{SD_SUFFIX}" for a in self.axis_labels]
        cols += ["status"]
        cols += [f"{c}.root.{a}" for c in self.chain_names for a in "xyz"]
        cols += [f"{p}.{a}" for p in (*self.marker_names, *self.joint_names) for a in "xyz"]
        if self.residuals is not None:
            cols += [f"{m}.res.{v}" for m in self.marker_names for v in self.view_names]
        return cols


def results_from_fit(body: Body, fit_results: Sequence, view_names: Sequence[str],
                     detections=None) -> Results:
    """Build :class:`Results` from the fitter's per-frame results (3D points by FK).

    ``detections`` (a :class:`videotrack.detect.detections.Detections`) supplies video frame, field
    and time of each record; without it the record index stands for all three.
    """
    n = len(fit_results)
    frames = np.array([r.frame for r in fit_results], dtype=np.int64)
    angles = np.array([r.angles_deg for r in fit_results], dtype=float).reshape(n, body.n_axes)
    roots = np.array([r.root_positions for r in fit_results], dtype=float).reshape(
        n, len(body.chains), 3)
    markers = np.full((n, len(body.marker_names), 3), np.nan)
    joints = np.full((n, len(body.joint_names), 3), np.nan)
    good = np.all(np.isfinite(angles), axis=1) & np.all(np.isfinite(roots), axis=(1, 2))
    if good.any():
        pose = forward_kinematics(pack_body(body), angles[good], roots[good])
        markers[good], joints[good] = pose.markers, pose.joints
    residuals = None
    if n and all(getattr(r, "marker_residuals", None) is not None for r in fit_results):
        # (n, v, m) from the fitter -> (n, m, v): one marker's views side by side
        residuals = np.array([r.marker_residuals for r in fit_results], dtype=float).reshape(
            n, len(view_names), len(body.marker_names)).transpose(0, 2, 1)
    quality = None
    if n and all(hasattr(r, "worst_px") for r in fit_results):
        quality = np.array([(r.matched, r.unexplained, r.worst_px) for r in fit_results],
                           dtype=float).reshape(n, 3)
    sd = None
    if n and any(getattr(r, "sd_deg", None) is not None for r in fit_results):
        sd = np.array([np.full(body.n_axes, np.nan) if r.sd_deg is None else r.sd_deg
                       for r in fit_results], dtype=float).reshape(n, body.n_axes)
    if detections is not None:
        video_frames = np.asarray(detections.video_frames)[frames]
        fields = np.asarray(detections.parities)[frames]
        times = np.asarray(detections.times)[frames]
    else:
        video_frames, fields, times = frames.copy(), np.full(n, -1), frames.astype(float)
    return Results(
        axis_labels=tuple(body.axis_labels), view_names=tuple(view_names),
        chain_names=tuple(c.name for c in body.chains),
        marker_names=tuple(body.marker_names), joint_names=tuple(body.joint_names),
        frames=frames, video_frames=np.asarray(video_frames, dtype=np.int64),
        fields=np.asarray(fields, dtype=np.int64), times=np.asarray(times, dtype=float),
        angles_deg=angles, error=np.array([r.error for r in fit_results], dtype=float),
        error_per_view=np.array([r.error_per_view for r in fit_results], dtype=float).reshape(
            n, len(view_names)),
        runs=np.array([r.runs for r in fit_results], dtype=np.int64),
        iterations=np.array([r.iterations for r in fit_results], dtype=np.int64),
        status=tuple(r.status for r in fit_results), roots=roots, markers=markers,
        joints=joints, residuals=residuals, quality=quality, sd=sd,
    )


def format_results(results: Results) -> str:
    """CSV text of the results (see the module docstring for the columns)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(results.columns)
    for i in range(len(results)):
        numbers = [results.frames[i], results.video_frames[i], results.fields[i],
                   results.times[i], *results.angles_deg[i], results.error[i],
                   *results.error_per_view[i], results.runs[i], results.iterations[i]]
        if results.quality is not None:
            numbers += [*results.quality[i]]
        if results.sd is not None:
            numbers += [*results.sd[i]]
        points = [*results.roots[i].ravel(), *results.markers[i].ravel(),
                  *results.joints[i].ravel()]
        if results.residuals is not None:
            points += [*results.residuals[i].ravel()]
        writer.writerow([*(format_cell(float(v)) for v in numbers), results.status[i],
                         *(format_cell(float(v)) for v in points)])
    return buf.getvalue()


def write_results(path: str | os.PathLike, results: Results, sidecar: Mapping,
                  candidates: tuple[Body, Sequence] | None = None) -> Path:
    """Write ``path`` (CSV) and ``path`` with suffix ``.json`` (the sidecar), atomically;
    with ``candidates`` (the body and the fit results) the candidates file too, first
    (:func:`write_candidates`).

    The CSV is written last, so a complete CSV always has a matching sidecar; the sidecar
    records the CSV's SHA-256 (``csv_sha256``), so a CSV left from an earlier run beside a
    newer sidecar is recognised, and the candidates file's (``candidates_sha256``, None
    for none), so a set cut by a failed write (a full disk) is seen as one
    (:func:`videotrack.workflow.staleness.results_stale_reason`).
    """
    path = Path(path)
    side = sidecar_path(path)
    text = format_results(results)
    extra = {}
    if candidates is not None:
        written = write_candidates(path, *candidates)
        extra["candidates_sha256"] = None if written is None else file_sha256(written)
    # The CSV's hash tells a complete pair from one cut between the two writes.
    meta = {"format": RESULTS_FORMAT, **sidecar, **extra, "rows": len(results),
            "csv_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest()}
    atomic_write_text(side, json.dumps(meta, indent=2, sort_keys=True) + "\n")
    atomic_write_text(path, text)
    return path


def candidates_path(path: str | os.PathLike) -> Path:
    """The candidates file beside a results file (``x.csv`` -> ``x.candidates.csv``)."""
    path = Path(path)
    stem = path.name[:-4] if path.name.lower().endswith(".csv") else path.name
    return path.with_name(stem + ".candidates.csv")


def format_candidates(body: Body, fit_results: Sequence) -> str:
    """CSV text of the candidate postures of ``fit_results`` (module docstring)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    chains = [c.name for c in body.chains]
    writer.writerow(["frame", "rank", "chosen", "error", *body.axis_labels,
                     *(f"{c}.root.{a}" for c in chains for a in "xyz")])
    for r in fit_results:
        ranked = sorted(r.candidates, key=lambda c: c.error)
        for rank, c in enumerate(ranked):
            chosen = int(np.array_equal(c.angles_deg, r.angles_deg))
            writer.writerow([r.frame, rank, chosen, format_cell(float(c.error)),
                             *(format_cell(float(v)) for v in c.angles_deg),
                             *(format_cell(float(v)) for v in np.ravel(c.root_positions))])
    return buf.getvalue()


def write_candidates(path: str | os.PathLike, body: Body, fit_results: Sequence) -> Path | None:
    """Write the candidates file beside results ``path`` (atomically). When no frame has
    candidates, nothing is written and a candidates file left by an earlier fit is removed
    (it would not match these results); None then."""
    out = candidates_path(path)
    if not any(getattr(r, "candidates", ()) for r in fit_results):
        out.unlink(missing_ok=True)
        return None
    atomic_write_text(out, format_candidates(body, fit_results))
    return out


def read_candidates(path: str | os.PathLike) -> dict[int, list[dict]]:
    """The candidates of a candidates file by frame: a list (by rank) of dicts with
    ``rank``, ``chosen``, ``error``, ``angles_deg`` (n_axes,) and ``root_positions``
    (n_chains, 3)."""
    path = Path(path)
    try:
        rows = list(csv.reader(io.StringIO(path.read_text(encoding="utf-8"))))
    except OSError as err:
        raise VideoTrackError(f"cannot read: {err.strerror or err}", file=path) from None
    if not rows or rows[0][:4] != ["frame", "rank", "chosen", "error"]:
        raise VideoTrackError("not a candidates file (its header must start with frame, "
                              "rank, chosen, error)", file=path, line=1)
    header = rows[0]
    n_roots = sum(1 for h in header if ".root." in h)
    n_axes = len(header) - 4 - n_roots
    out: dict[int, list[dict]] = {}
    for line, row in enumerate(rows[1:], start=2):
        try:
            if len(row) != len(header):
                raise ValueError(f"{len(row)} cells, the header has {len(header)}")
            values = np.array([float(v) if v else np.nan for v in row[3:]])
            frame, rank, chosen = int(row[0]), int(row[1]), int(row[2])
        except ValueError as err:
            raise VideoTrackError(f"bad row: {err}", file=path, line=line) from None
        out.setdefault(frame, []).append({
            "rank": rank, "chosen": bool(chosen), "error": float(values[0]),
            "angles_deg": values[1: 1 + n_axes],
            "root_positions": values[1 + n_axes:].reshape(-1, 3)})
    return out


def attach_candidates(results: Mapping[int, object], path: str | os.PathLike) -> dict:
    """``results`` (frame -> FrameResult) with the candidate postures of the candidates file
    beside results ``path`` (when there is one): the chosen posture first, then the others
    by rank, as the fitter gives them."""
    from dataclasses import replace

    from kinematics.fit import Candidate

    out = dict(results)
    found_path = candidates_path(path)
    if not found_path.exists():
        return out
    for frame, rows in read_candidates(found_path).items():
        if frame in out:
            rows = sorted(rows, key=lambda c: (not c["chosen"], c["rank"]))
            out[frame] = replace(out[frame], candidates=tuple(
                Candidate(c["angles_deg"], c["root_positions"], c["error"], None, None, None)
                for c in rows))
    return out


def sidecar_path(path: str | os.PathLike) -> Path:
    path = Path(path)
    return path.with_name(path.name + ".json")


def read_sidecar(path: str | os.PathLike) -> dict:
    """The sidecar of a results file ({} when absent)."""
    side = sidecar_path(path)
    if not side.exists():
        return {}
    try:
        return json.loads(side.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise VideoTrackError(f"unreadable results sidecar ({err})", file=side) from None


def read_results(path: str | os.PathLike) -> Results:
    """Read a results CSV written by :func:`write_results` (names come from its header)."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
    except FileNotFoundError:
        raise VideoTrackError("no such results file", file=path) from None
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise VideoTrackError(f"cannot read results: {err}", file=path) from None
    if not rows or rows[0][:4] != ["frame", "video_frame", "field", "time"]:
        raise VideoTrackError("not a VideoTrack results file (header must start with "
                              "frame,video_frame,field,time)", file=path, line=1)
    header = rows[0]
    try:
        i_err, i_runs, i_status = (header.index(k) for k in ("error", "runs", "status"))
    except ValueError as err:
        raise VideoTrackError(f"results header lacks a column ({err})", file=path,
                              line=1) from None
    axis_labels = tuple(header[4:i_err])
    views = tuple(h[len("error."):] for h in header[i_err + 1:i_runs])
    res_cols = [c for c, h in enumerate(header) if ".res." in h]
    i_res = res_cols[0] if res_cols else len(header)
    point_cols = header[i_status + 1:i_res]
    chains = tuple(h[:-len(".root.x")] for h in point_cols[::3] if h.endswith(".root.x"))
    names = [h[:-2] for h in point_cols[3 * len(chains)::3]]
    side = read_sidecar(path)
    n_markers = int(side.get("markers", len(names)))
    data = np.full((len(rows) - 1, len(header)), np.nan)
    status = []
    for r, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise VideoTrackError(f"row has {len(row)} cells, header has {len(header)}",
                                  file=path, line=r + 2)
        for c, cell in enumerate(row):
            if c == i_status:
                if cell not in STATUSES:
                    raise VideoTrackError(f"unknown status '{cell}'", file=path, line=r + 2,
                                          field="status")
                status.append(Status(cell))
            elif cell:
                try:
                    data[r, c] = float(cell)
                except ValueError:
                    raise VideoTrackError(f"'{cell}' is not a number", file=path, line=r + 2,
                                          field=header[c]) from None
    n = data.shape[0]
    points = data[:, i_status + 1:i_res].reshape(n, -1, 3)
    quality = None
    i_sd = next((c for c in range(i_runs + 2, i_status) if header[c].endswith(SD_SUFFIX)),
                i_status)
    if tuple(header[i_runs + 2:i_sd]) == QUALITY_COLUMNS:
        quality = data[:, i_runs + 2:i_sd]
    sd = None
    if i_sd < i_status:
        if header[i_sd:i_status] != [f"{a}{SD_SUFFIX}" for a in axis_labels]:
            raise VideoTrackError("sd columns do not match the axes", file=path, line=1)
        sd = data[:, i_sd:i_status]
    residuals = None
    if res_cols:
        res_views = tuple(dict.fromkeys(h.rsplit(".res.", 1)[1] for h in header[i_res:]))
        if res_views != views or len(header) - i_res != n_markers * len(views):
            raise VideoTrackError("residual columns do not match the markers and views",
                                  file=path, line=1)
        residuals = data[:, i_res:].reshape(n, n_markers, len(views))
    nc = len(chains)
    return Results(
        axis_labels=axis_labels, view_names=views, chain_names=chains,
        marker_names=tuple(names[:n_markers]), joint_names=tuple(names[n_markers:]),
        frames=data[:, 0].astype(np.int64), video_frames=data[:, 1].astype(np.int64),
        fields=data[:, 2].astype(np.int64), times=data[:, 3],
        angles_deg=data[:, 4:i_err], error=data[:, i_err],
        error_per_view=data[:, i_err + 1:i_runs], runs=data[:, i_runs].astype(np.int64),
        iterations=data[:, i_runs + 1].astype(np.int64), status=tuple(status),
        roots=points[:, :nc], markers=points[:, nc:nc + n_markers],
        joints=points[:, nc + n_markers:], residuals=residuals, quality=quality, sd=sd,
    )


def frame_results(table: Results, seed: int) -> dict:
    """The rows of a results table as the fitter's ``FrameResult`` records, keyed by frame
    (to resume a fit, or to edit results in the GUI)."""
    from kinematics.fit import FrameResult

    return {
        int(table.frames[i]): FrameResult(
            frame=int(table.frames[i]), angles_deg=np.array(table.angles_deg[i]),
            error=float(table.error[i]), error_per_view=np.array(table.error_per_view[i]),
            runs=int(table.runs[i]), iterations=int(table.iterations[i]), seed=int(seed),
            status=table.status[i], root_positions=np.array(table.roots[i]),
            marker_residuals=(None if table.residuals is None
                              else np.array(table.residuals[i]).T),
            sd_deg=None if table.sd is None else np.array(table.sd[i]),
            **({} if table.quality is None else {
                "matched": int(table.quality[i, 0]) if np.isfinite(table.quality[i, 0])
                else 0,
                "unexplained": int(table.quality[i, 1]) if np.isfinite(table.quality[i, 1])
                else 0,
                "worst_px": float(table.quality[i, 2])}))
        for i in range(len(table))
    }


def file_sha256(path: str | os.PathLike) -> str:
    """Content hash recorded in sidecars (which inputs produced a result): the SHA-256 of
    the file, cached while the file is unchanged (:func:`videotrack.project.identity.content_hash`).
    """
    from videotrack.project.identity import content_hash

    return content_hash(path)
