"""Fitting a body to observations: the :class:`Fitter` and the records it gives.

The fitter is one class assembled from one module per job (see docs/architecture.md):

- :mod:`~kinematics.fit.fitter` — the public API: observations in, results out;
- :mod:`~kinematics.fit.match` — where markers are matched (per view or in 3D);
- :mod:`~kinematics.fit.roots` — root markers tracked, free roots placed;
- :mod:`~kinematics.fit.dispatch` — which kernel fits a block (scalar, lanes, CUDA);
- :mod:`~kinematics.fit.status` — a fitted posture scored and judged;
- :mod:`~kinematics.fit.candidates` — distinct postures and re-fits from a neighbour;
- :mod:`~kinematics.fit.path` — the path through time;
- :mod:`~kinematics.fit.tracking` — ``start = "track"``;
- :mod:`~kinematics.fit.polish` — the final least-squares polish against a cloud;
- :mod:`~kinematics.fit.flags` — flags over a sequence of results;
- :mod:`~kinematics.fit.confidence` — set-up checks and the noise test of every frame
  (:mod:`~kinematics.fit.noise`, :mod:`~kinematics.fit.setup_check`);
- :mod:`~kinematics.fit.tuning` — the measured constants, in one record;
- :mod:`~kinematics.fit.reference` — the annealing loop written plainly (the twin).
"""

from kinematics.fit.candidates import concurrent_fits
from kinematics.fit.fitter import Fitter, fit_frame, iter_fit
from kinematics.fit.flags import flag_e_spikes, flag_misplaced, misplaced
from kinematics.fit.inputs import unseen_markers
from kinematics.fit.reference import SplitMix64, anneal_reference
from kinematics.fit.result import (
    ATTENTION,
    SCORED,
    STATUSES,
    TRUSTED,
    WITHIN,
    Candidate,
    FrameResult,
    Status,
)
from kinematics.fit.settings import START_MODES, AnnealParams, ErrorOptions
from kinematics.fit.setup_check import SetupError
from kinematics.fit.status import auto_threshold, marker_images
from kinematics.fit.tuning import TUNING, Tuning

__all__ = [
    "ATTENTION",
    "SCORED",
    "START_MODES",
    "STATUSES",
    "TRUSTED",
    "TUNING",
    "WITHIN",
    "AnnealParams",
    "Candidate",
    "ErrorOptions",
    "Fitter",
    "FrameResult",
    "SetupError",
    "SplitMix64",
    "Status",
    "Tuning",
    "anneal_reference",
    "auto_threshold",
    "concurrent_fits",
    "fit_frame",
    "flag_e_spikes",
    "flag_misplaced",
    "iter_fit",
    "marker_images",
    "misplaced",
    "unseen_markers",
]
