"""The settings of a fit as frozen records: :class:`AnnealParams` (the paper's Table 1 and
what the fitter adds) and :class:`ErrorOptions` (which error function, Eq. 5 or a variant).

One source per setting: the project file's ``[anneal]`` section is derived from these records
(their fields, defaults and docs), so every field here is settable in a project file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np

from kinematics.errors import KinematicsError

START_MODES = ("mean", "previous")

#: Cost of a marker with no finite projection when no cap is set (same as the kernels).
NAN_MARKER_COST = 1.0e6

ERROR_MODES = ("paper", "bidirectional")


@dataclass(frozen=True)
class ErrorOptions:
    """Which error function the fit minimises.

    Parameters
    ----------
    mode : {"paper", "bidirectional"}
        ``"paper"`` is Eq. 5; ``"bidirectional"`` adds the Sect. 4 penalty for detections
        that no model marker claims.
    penalty_weight : float
        Weight of that penalty (bidirectional only), >= 0.
    cap_px : float or None
        Largest cost of one marker (and of one unclaimed detection) in pixels; None for no
        cap (the paper).
    """

    mode: str = "paper"
    penalty_weight: float = 1.0
    cap_px: float | None = None

    def __post_init__(self) -> None:
        if self.mode not in ERROR_MODES:
            raise KinematicsError(f"must be one of {', '.join(ERROR_MODES)}, got {self.mode!r}",
                                  field="error.mode")
        if not (np.isfinite(self.penalty_weight) and self.penalty_weight >= 0):
            raise KinematicsError(f"must be a finite number >= 0, got {self.penalty_weight!r}",
                                  field="error.penalty_weight")
        if self.cap_px is not None and not (np.isfinite(self.cap_px) and self.cap_px > 0):
            raise KinematicsError(f"must be a finite number > 0 or None, got {self.cap_px!r}",
                                  field="error.cap_px")

    @property
    def bidirectional(self) -> bool:
        return self.mode == "bidirectional"

    @property
    def cap(self) -> float:
        """The cap as a number (inf without a cap), as the kernels take it."""
        return np.inf if self.cap_px is None else float(self.cap_px)

    def to_dict(self) -> dict:
        return {"mode": self.mode, "penalty_weight": self.penalty_weight, "cap_px": self.cap_px}



# -- parameters -----------------------------------------------------------------------------
@dataclass(frozen=True)
class AnnealParams:
    """Parameters of the fit; the defaults are the paper's Table 1 and its note.

    Parameters
    ----------
    n_end : int
        N_end, iterations per run (35 000).
    n_l, n_tau : int
        N_l and N_τ: the step length l is multiplied by ``c_l`` every ``n_l`` iterations
        (3500), the temperature τ by ``c_tau`` every ``n_tau`` (1500).
    tau0 : float
        τ0, start temperature in pixels of E (200).
    l0 : float
        l, start step length in units of s(H) (1).
    c_l, c_tau : float
        Cooling factors in (0, 1] (0.75).
    epsilon : float
        ε: a run stops once E < ε pixels (1).
    plausibility_threshold : float or None
        T_h: a step component v_i is redrawn while ``H_i(j_i + l·v_i) < T_h``. None (default)
        means "any non-zero bin is plausible" (redraw only where the histogram is empty: the
        paper's initial histograms are uniform over the range, so this keeps every axis in
        its range). A number compares with the bin probability itself, e.g. ``0.2 / n_bins``
        to avoid bins visited five times less often than average.
    max_redraws : int
        Redraws of one component before the axis stays still for that iteration (16).
    reanalysis_threshold : float
        A frame whose final E exceeds this (pixels) is fitted again (10, Table 1 note).
    max_runs : int
        Runs per frame at most, the first included (5).
    start : {"mean", "previous"}
        Start posture of a frame's first run (see the module doc for the trade-off).
    segment_length : int
        Frames per independent segment with ``start="previous"``.
    refine : bool
        Polish every fitted posture by Levenberg-Marquardt (:mod:`kinematics.refine`); off
        by default so the defaults reproduce the paper.
    refine_steps : int
        Accepted LM steps at most.
    refine_gate_px : float
        Marker/detection pairs farther apart than this are ignored by refinement.
    root_gate_px : float or None
        Root-marker tracking ignores a view whose nearest detection is farther than this from
        the predicted root marker; None: no gate (the paper's nearest neighbour).
    error : ErrorOptions
        Error function: Eq. 5 (default) or a variant.
    seed : int
        Seed of the random streams, >= 0; recorded in every result.
    """

    n_end: int = 35000
    n_l: int = 3500
    n_tau: int = 1500
    tau0: float = 200.0
    l0: float = 1.0
    c_l: float = 0.75
    c_tau: float = 0.75
    epsilon: float = 1.0
    plausibility_threshold: float | None = None
    max_redraws: int = 16
    reanalysis_threshold: float = 10.0
    max_runs: int = 5
    start: str = "mean"
    segment_length: int = 32
    refine: bool = False
    refine_steps: int = 10
    refine_gate_px: float = 5.0
    root_gate_px: float | None = None
    error: ErrorOptions = field(default_factory=ErrorOptions)
    seed: int = 0

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`KinematicsError` naming the first invalid field."""
        ints = {"n_end": 1, "n_l": 1, "n_tau": 1, "max_redraws": 0, "max_runs": 1,
                "segment_length": 1, "refine_steps": 0, "seed": 0}
        for name, least in ints.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or (
                    value < least):
                raise KinematicsError(f"must be an integer >= {least}, got {value!r}",
                                      field=name)
        if self.seed >= 2**63:
            raise KinematicsError(f"must be below 2**63, got {self.seed}", field="seed")
        positive = ("tau0", "l0", "reanalysis_threshold", "refine_gate_px")
        for name in positive:
            value = getattr(self, name)
            if not _is_real(value) or not (math.isfinite(value) and value > 0):
                raise KinematicsError(f"must be a finite number > 0, got {value!r}",
                                      field=name)
        for name in ("c_l", "c_tau"):
            value = getattr(self, name)
            if not _is_real(value) or not 0 < value <= 1:
                raise KinematicsError(f"must be in (0, 1], got {value!r}", field=name)
        if not _is_real(self.epsilon) or not (math.isfinite(self.epsilon)
                                              and self.epsilon >= 0):
            raise KinematicsError(f"must be a finite number >= 0, got {self.epsilon!r}",
                                  field="epsilon")
        th = self.plausibility_threshold
        if th is not None and not (_is_real(th) and math.isfinite(th) and 0 <= th <= 1):
            raise KinematicsError(f"must be None or a number in [0, 1], got {th!r}",
                                  field="plausibility_threshold")
        g = self.root_gate_px
        if g is not None and not (_is_real(g) and g > 0):
            raise KinematicsError(f"must be None or a number > 0, got {g!r}",
                                  field="root_gate_px")
        if self.start not in START_MODES:
            raise KinematicsError(f"must be one of {', '.join(START_MODES)}, got "
                                  f"{self.start!r}", field="start")
        if not isinstance(self.refine, bool | np.bool_):
            raise KinematicsError(f"must be true or false, got {self.refine!r}",
                                  field="refine")
        if not isinstance(self.error, ErrorOptions):
            raise KinematicsError("must be an ErrorOptions", field="error")

    @property
    def threshold(self) -> float:
        """T_h as the kernels compare it: ``H < threshold`` is implausible. None becomes the
        smallest positive double, so exactly the empty bins are implausible."""
        th = self.plausibility_threshold
        return float(np.nextafter(0.0, 1.0)) if th is None else float(th)

    def with_schedule(self, n_end: int) -> AnnealParams:
        """The same cooling schedule compressed or stretched to ``n_end`` iterations: N_l and
        N_τ scale linearly, as in the paper's sensitivity analysis (Sect. 3.2)."""
        scale = n_end / self.n_end
        return replace(self, n_end=int(n_end), n_l=max(1, round(self.n_l * scale)),
                       n_tau=max(1, round(self.n_tau * scale)))

    def to_dict(self) -> dict:
        """Plain values for a results sidecar (``error`` as a nested dict)."""
        d = asdict(self)
        d["error"] = self.error.to_dict()
        return d

    @classmethod
    def from_dict(cls, values: Mapping) -> AnnealParams:
        """Build from plain values (e.g. a project file section); unknown keys are errors."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise KinematicsError(f"unknown annealing parameter '{unknown[0]}'",
                                  field=unknown[0])
        kw = dict(values)
        if isinstance(kw.get("error"), Mapping):
            kw["error"] = ErrorOptions(**kw["error"])
        return cls(**kw)


def _is_real(value) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_)


