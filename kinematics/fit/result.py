"""What a fit gives: one frame's result and its candidate postures.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum
from typing import NamedTuple

import numpy as np


class Status(StrEnum):
    """What a frame's result says of itself; each equals the word results files hold."""

    OK = "ok"  # E within the threshold at the first run
    REANALYSED = "reanalysed"  # ... after re-runs
    AMBIGUOUS = "ambiguous"  # within it, but another posture fits about as well
    FAILED = "failed"  # E above the threshold after every run
    NO_DETECTIONS = "no-detections"  # nothing to fit
    CORRECTED = "corrected"  # set by a person (the GUI), never by a fit


#: The statuses a fit gives, in the order summaries list them.
STATUSES = tuple(s for s in Status if s is not Status.CORRECTED)
#: E within the threshold: the fit's own verdict of a right frame.
WITHIN = frozenset({Status.OK, Status.REANALYSED})
#: Results to build on (learning histograms, counting good frames): within, or corrected.
TRUSTED = WITHIN | {Status.CORRECTED}
#: Results whose E the fit compared with its threshold (drawn good or bad by E).
SCORED = WITHIN | {Status.FAILED}
#: Results that ask a person for a look.
ATTENTION = frozenset({Status.FAILED, Status.REANALYSED, Status.AMBIGUOUS})


class Candidate(NamedTuple):
    """One distinct posture a frame's runs found (``AnnealParams.candidates`` > 1)."""

    angles_deg: np.ndarray  # (n_axes,)
    root_positions: np.ndarray  # (n_chains, 3)
    error: float
    state: np.ndarray  # (n_state,) the kernels' state (for re-scoring) ...
    seed_pos: np.ndarray  # (n_chains, 3) ... relative to these root seeds
    seed_rot: np.ndarray  # (n_chains, 3, 3)


@dataclass(frozen=True, eq=False)
class FrameResult:
    """The fit of one frame.

    Attributes
    ----------
    frame : int
        Index of the frame (record) in the detections.
    angles_deg : ndarray, shape (n_axes,)
        Fitted posture, each angle expressed within its axis range where possible; NaN when
        the frame had no detections.
    error : float
        E of the fitted posture (Eq. 5 or the chosen variant), pixels; the confidence value.
    error_per_view : ndarray, shape (n_views,)
        The part of E from each view (NaN without detections; 0 for a view without any).
    runs : int
        Annealing runs made (1 + re-analyses).
    iterations : int
        Annealing iterations over all runs.
    seed : int
        The seed; run r drew from the stream of (seed, frame, r).
    status : Status
        ``"ok"`` (E within the threshold at the first run; runs made for candidates or to
        confirm a result, ``confirm_runs``, are no re-analyses), ``"reanalysed"`` (within it
        after re-runs), ``"ambiguous"`` (within it, but another candidate posture far from
        this one, ``ambiguous_deg`` on an axis and ``ambiguous_move`` at a marker, fits about
        as well, or the chosen posture jumps from a neighbour's and no re-fit found one that
        continues the movement: see ``candidates``; or, matching in 3D, a limb has a marker
        that neither a cloud point nor two views place), ``"failed"`` (above it after
        ``max_runs``), ``"no-detections"``.
    root_positions : ndarray, shape (n_chains, 3)
        Root of each chain used for this frame (configured or tracked).
    missing_views : tuple of str
        Views without any detection in this frame (fitted from the others).
    dropped : int
        Detected points dropped because a coordinate was NaN or infinite.
    refined_pairs : int or None
        Marker/detection pairs used by refinement, None when refinement was off.
    marker_residuals : ndarray, shape (n_views, n_markers), or None
        Distance in pixels from each fitted model marker to its nearest detection in each
        view (NaN where the view has no detection): which marker is off.
    matched : int
        Marker images (marker × view) within ``claim_gate_px`` of a detection.
    unexplained : int
        Detections farther than ``claim_gate_px`` from every model marker (ghosts, or
        markers the fit left out).
    worst_px : float
        The largest marker residual (NaN without one).
    candidates : tuple of Candidate
        With ``candidates`` > 1: the frame's distinct postures, lowest E first (this
        result's posture among them); empty otherwise.
    threshold : float
        The re-analysis threshold on E that decided the status: with ``threshold_mode``
        'auto' the one measured on the video, which a front end should show as its bar
        (NaN for results not made by a fit).
    sd_deg : ndarray, shape (n_axes,), or None
        Per axis, the standard deviation of the angle in degrees given the noise model
        (:mod:`kinematics.fit.uncertainty`): 0 for locked or pinned axes, widened by the
        candidates' spread where ``ambiguous``; None where no noise model was measured.
    """

    frame: int
    angles_deg: np.ndarray
    error: float
    error_per_view: np.ndarray
    runs: int
    iterations: int
    seed: int
    status: Status
    root_positions: np.ndarray
    missing_views: tuple[str, ...] = ()
    dropped: int = 0
    refined_pairs: int | None = None
    marker_residuals: np.ndarray | None = None
    matched: int = 0
    unexplained: int = 0
    worst_px: float = float("nan")
    candidates: tuple = ()
    threshold: float = float("nan")
    sd_deg: np.ndarray | None = None

    @property
    def spread_deg(self) -> np.ndarray:
        """Per axis, how far apart the frame's candidate postures are (largest minus smallest,
        degrees, turns wrapped); zeros with fewer than two candidates. Axes with a spread
        are the ones the frame is unsure about."""
        if len(self.candidates) < 2:
            return np.zeros(np.size(self.angles_deg))
        a = np.array([c.angles_deg for c in self.candidates], float)
        d = (a - a[0] + 180.0) % 360.0 - 180.0  # each relative to the chosen posture
        return d.max(axis=0) - d.min(axis=0)

    @property
    def ok(self) -> bool:
        """True for ``ok`` and ``reanalysed`` frames (E within the threshold)."""
        return self.status in WITHIN


def reanalysed(r: FrameResult) -> FrameResult:
    """``r`` made ``reanalysed`` where it is ``ok`` (a result that replaced another)."""
    return replace(r, status=Status.REANALYSED if r.status == Status.OK else r.status)
