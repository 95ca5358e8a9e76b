"""The settings of a fit as frozen records: :class:`AnnealParams` (the paper's Table 1 and
what the fitter adds) and :class:`ErrorOptions` (which error function, Eq. 5 or a variant).

One source per setting: every field is declared with :func:`setting`, which holds its
user-facing metadata (doc, bounds, choices) in the field's ``metadata``. The project file's
``[anneal]`` section (:mod:`videotrack.project.config`), its reference in docs/config.md and the
GUI's
form are derived from these fields, so a field added here is settable in a project file
without further edits. ``__post_init__`` validation stays here and is what every caller gets.

Metadata keys (all optional but ``doc``):

``doc``
    One or two sentences for the config reference and tool tips.
``min``, ``max``
    Inclusive bounds a project file may give (finite: the GUI's spin boxes need them). The
    record's own validation may be stricter (e.g. ``> 0``); it is checked when the record is
    built.
``choices``
    The allowed values of a string field.
``none``
    For a field that may be None: the value a project file writes for None (TOML has no
    null), e.g. ``0.0``. The doc says what None means.
``flatten``
    For a field that is itself a record (``AnnealParams.error``): its fields become keys of
    the same section; the mapping renames some of them (``{"mode": "error"}``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np

from kinematics.errors import KinematicsError


def setting(default, doc: str, *, min=None, max=None, choices=None, none=None):
    """A dataclass field with a default and its user-facing metadata (see the module doc)."""
    meta = {"doc": doc, "min": min, "max": max, "choices": choices, "none": none}
    return field(default=default, metadata={k: v for k, v in meta.items() if v is not None})


START_MODES = ("mean", "previous", "track")
PARTITION_MODES = ("auto", "none")
BACKENDS = ("auto", "scalar", "lanes", "cuda")
PRECISIONS = ("float64", "float32")
MATCH_MODES = ("auto", "views", "3d")
THRESHOLD_MODES = ("absolute", "auto")
CONFIRM_MODES = ("auto", "on", "off")

#: Cost of a marker with no finite projection when no cap is set (same as the kernels).
NAN_MARKER_COST = 1.0e6

ERROR_MODES = ("paper", "bidirectional", "bounded")


@dataclass(frozen=True)
class ErrorOptions:
    """Which error function the fit minimises (the fields' metadata say what each means)."""

    mode: str = setting(
        "paper", "Error function: the paper's Eq. 5 ('paper'), the variant of Sect. 4 "
        "('bidirectional') that also penalises detections no model marker claims, or that "
        "variant with each unclaimed detection costing at most penalty_cap_px ('bounded', "
        "safe with ghost markers).", choices=ERROR_MODES)
    penalty_weight: float = setting(
        1.0, "Weight of the bidirectional penalty for detections no marker claims.",
        min=0.0, max=1e6)
    cap_px: float | None = setting(
        None, "Largest cost of one marker (and of one unclaimed detection) in pixels, so an "
        "occlusion costs at most this; None, written 0 in a project file: no cap (the paper).",
        min=0.0, max=1e9, none=0.0)
    penalty_cap_px: float = setting(
        3.0, "Largest cost of one unclaimed detection in pixels with error 'bounded' (a ghost "
        "marker costs at most penalty_weight times this).", min=1e-6, max=1e9)
    one_to_one: bool = setting(
        False, "Each detection (in 3D: each triangulated point) explains at most one model "
        "marker: where several markers have one as their nearest, the closest keeps it and "
        "each other takes its nearest free one, so two limbs cannot share a blob.")

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
        if not (np.isfinite(self.penalty_cap_px) and self.penalty_cap_px > 0):
            raise KinematicsError(f"must be a finite number > 0, got {self.penalty_cap_px!r}",
                                  field="error.penalty_cap_px")
        if not isinstance(self.one_to_one, bool | np.bool_):
            raise KinematicsError(f"must be true or false, got {self.one_to_one!r}",
                                  field="error.one_to_one")

    @property
    def bidirectional(self) -> bool:
        """Whether unclaimed detections add a penalty (modes bidirectional and bounded)."""
        return self.mode in ("bidirectional", "bounded")

    @property
    def penalty_cap(self) -> float:
        """Largest cost of one unclaimed detection as the kernels take it: the marker cap
        for 'bidirectional' (as the paper's heuristic), ``penalty_cap_px`` for 'bounded'."""
        return float(self.penalty_cap_px) if self.mode == "bounded" else self.cap

    @property
    def cap(self) -> float:
        """The cap as a number (inf without a cap), as the kernels take it."""
        return np.inf if self.cap_px is None else float(self.cap_px)

    def to_dict(self) -> dict:
        return {"mode": self.mode, "penalty_weight": self.penalty_weight, "cap_px": self.cap_px,
                "penalty_cap_px": self.penalty_cap_px, "one_to_one": self.one_to_one}



# -- parameters -----------------------------------------------------------------------------
@dataclass(frozen=True)
class AnnealParams:
    """Parameters of the fit. The defaults are the best measured settings (Table 1's
    schedule, refinement, the bounded error with a 10-px marker cap, the status threshold
    measured on the video, two candidate postures per frame and the path through time:
    docs/benchmarks.md, "Defaults"); :meth:`paper` gives the paper's own (Table 1 and its
    note, Eq. 5), which reproduce Table 2.

    The fields' metadata (:func:`setting`) say what each means; docs/fitting.md says how to
    tune them.
    """

    n_end: int = setting(35000, "N_end: iterations of one annealing run (Table 1); a body "
                         "annealed in partitions shares them among its partitions by their "
                         "free axes, in each round (N_l and N_τ likewise).",
                         min=1, max=10**8)
    n_l: int = setting(3500, "N_l: the step length is multiplied by c_l every N_l iterations.",
                       min=1, max=10**8)
    n_tau: int = setting(1500, "N_τ: the temperature is multiplied by c_tau every N_τ "
                         "iterations.", min=1, max=10**8)
    tau0: float = setting(200.0, "τ0: start temperature, in pixels of E; > 0.",
                          min=0.0, max=1e9)
    l0: float = setting(1.0, "l: start step length, in units of s(H); > 0.", min=0.0, max=1e3)
    c_l: float = setting(0.75, "c_l: step-length cooling factor, in (0, 1].", min=1e-6,
                         max=1.0)
    c_tau: float = setting(0.75, "c_τ: temperature cooling factor, in (0, 1].", min=1e-6,
                           max=1.0)
    epsilon: float = setting(1.0, "ε: a run stops once E < ε pixels (0: always run N_end).",
                             min=0.0, max=1e9)
    plausibility_threshold: float | None = setting(
        None, "T_h: a step component is redrawn while its histogram bin's probability is "
        "below this. None, written 0 in a project file, means 'any non-zero bin' (redraw only "
        "where the histogram is empty, which keeps every axis in the range of the paper's "
        "uniform initial histograms); e.g. 0.2 / n_bins avoids bins visited five times less "
        "often than average.", min=0.0, max=1.0, none=0.0)
    max_redraws: int = setting(16, "Redraws of one step component before that axis stays still "
                               "for the iteration.", min=0, max=10**6)
    reanalysis_threshold: float = setting(
        10.0, "A frame whose final E exceeds this (pixels) is fitted again (Table 1 note); "
        "> 0.", min=0.0, max=1e9)
    max_runs: int = setting(8, "Runs per frame at most, the first included (the paper: 5).",
                            min=1, max=1000)
    start: str = setting("mean", "Start posture of a frame's first run: the histogram means "
                         "(frames independent), the previous frame's result, or 'track': "
                         "a short cold anneal from the previous frame's result, a full fit "
                         "where E is high or jumps, limbs merged and segments mended across "
                         "their edges; a frame whose E spikes is ambiguous (video filmed fast; "
                         "see docs/fitting.md).",
                         choices=START_MODES)
    segment_length: int = setting(32, "Frames per independent segment with start = "
                                  "'previous' or 'track' (each segment starts from the "
                                  "means).",
                                  min=1, max=10**8)
    refine: bool = setting(True, "Polish every fitted posture by Levenberg-Marquardt (see "
                           "docs/fitting.md); off in the paper profile.")
    refine_steps: int = setting(10, "Accepted Levenberg-Marquardt steps at most (refine).",
                                min=0, max=10**6)
    refine_gate_px: float = setting(5.0, "Refinement ignores marker/detection pairs farther "
                                    "apart than this (pixels); > 0.", min=0.0, max=1e9)
    final_polish_px: float | None = setting(
        50.0, "With matching in 3D: after the fit, each frame's chosen posture is fitted by "
        "least squares to its cloud points within this distance (px-equivalents), each "
        "point paired with one marker; a marker without a point is placed by its "
        "detections in two views, and a limb with a marker nothing places is held and makes "
        "the frame 'ambiguous' where the frame's runs, or the next frame's, put that limb "
        "ambiguous_move segment lengths apart. Kept though E grows a little (not across the "
        "threshold). "
        "Annealing minimises a sum of distances, which leaves the whole misfit of a limb "
        "the rigid chain cannot fit on one joint; least squares spreads it over the limb "
        "(docs/fitting.md, 'The final polish'). None, written 0 in a project file: off "
        "(the paper).",
        min=0.0, max=1e9, none=0.0)
    root_gate_px: float | None = setting(
        None, "Root-marker tracking ignores a view whose nearest detection is farther than "
        "this (pixels) from the predicted root marker; None, written 0 in a project file: no "
        "gate (the paper's nearest neighbour).", min=0.0, max=1e9, none=0.0)
    threshold_mode: str = setting(
        "auto", "How the re-analysis threshold is set: 'absolute' uses "
        "reanalysis_threshold (E in pixels, the paper's Table 1 note); 'auto' measures the "
        "video first — a sample of frames is fitted once and the threshold per marker image "
        "is median + auto_k MADs of their E per marker image (at least auto_floor_px) — so "
        "the status adapts to the marker and camera count and the noise of the recording.",
        choices=THRESHOLD_MODES)
    auto_k: float = setting(6.0, "With threshold_mode 'auto': how many robust standard "
                            "deviations (1.4826 MAD) above the median E per marker image a "
                            "frame may be before it is re-analysed and flagged.",
                            min=0.0, max=1e3)
    auto_floor_px: float = setting(0.5, "With threshold_mode 'auto': the smallest threshold "
                                   "per marker image (pixels); > 0.", min=1e-6, max=1e6)
    auto_sample: int = setting(64, "With threshold_mode 'auto': frames fitted to measure the "
                               "video (evenly spaced; all if fewer).", min=3, max=10**6)
    max_unexplained: int | None = setting(
        None, "A frame is re-analysed (and failed) also when more detections than this lie "
        "farther than claim_gate_px from every model marker: a limb on another limb's blobs "
        "leaves its own unexplained. The count is summed over the views. None, written -1 "
        "in a project file: not used (ghost markers are unexplained too; set it to the "
        "ghosts a frame shows in all its views).",
        min=-1, max=10**6, none=-1)
    noise_floor_px: float | None = setting(
        0.5, "The noise model: each view's detection noise σ is measured on the video's "
        "best-fitting frames (at least this, pixels), and a frame whose marker residuals "
        "are not what σ allows is 'failed' however low its E: a marker image beyond the gate "
        "(4-5 σ, wider with more marker images) from its detection that no missing detection "
        "excuses, or residuals whose sum of "
        "squares in σ passes the χ² test (docs/concepts.md, 'What a status means'). None, "
        "written 0 in a project file: no noise test (the paper: E against the threshold "
        "only).", min=0.0, max=1e6, none=0.0)
    noise_px: float | None = setting(
        None, "σ of the detection noise in every view (pixels), where it is known; None, "
        "written 0 in a project file: measured on the video (noise_floor_px).",
        min=0.0, max=1e6, none=0.0)
    accept_setup: bool = setting(
        False, "Fit although the set-up checks find the cameras, views, chain or video "
        "wrong (views that disagree in 3D, a chain that does not fit the detections, a "
        "video without markers); the problems are kept as warnings of the results. False: "
        "such a fit is refused with the cause in one line.")
    partitions: str = setting(
        "auto", "How a body is annealed: 'auto' anneals each limb in turn (every chain, and "
        "every subtree below a joint with several children, after its trunk), 'none' moves "
        "every axis at once (the paper; a single unbranched chain is one partition either "
        "way).", choices=PARTITION_MODES)
    partition_rounds: int = setting(
        2, "Rounds over the partitions per run; from the second on, a partition may not use "
        "the detections the other partitions' markers explain (limbs cannot share or take "
        "each other's markers).", min=1, max=100)
    start_samples: int | None = setting(
        None, "Start search: before a partition is annealed in a run's first round, its axes "
        "are drawn joint by joint from its base outward (32 x this many draws per joint, "
        "uniform within the ranges, plausible by the histograms), each joint's 32 best postures "
        "kept, and the best of all, polished, starts the annealing; in that round a "
        "partition may not use the detections the partitions fitted before it explain. A "
        "limb then starts on its own markers instead of wherever the start posture puts it "
        "(docs/fitting.md, 'Many limbs'). 0: every run starts from the start posture (the "
        "paper). None, written -1 in a project file: 64 for a body annealed in several "
        "partitions, 0 for one.", min=-1, max=10**5, none=-1)
    claim_gate_px: float = setting(
        10.0, "A marker of another partition claims its nearest detection only within this "
        "distance (pixels): an occluded marker claims nothing.", min=1e-6, max=1e9)
    candidates: int = setting(
        2, "Candidate postures kept per frame: every frame is annealed at least this many "
        "times (on its own random streams), distinct results are kept, and a path through "
        "time chooses one per frame (see docs/fitting.md, 'Candidates and the path'); 1: one "
        "answer per frame (the paper).", min=1, max=64)
    path_weight: float = setting(
        1.0, "With candidates > 1: weight of the movement's continuity against E when the "
        "path chooses; 0 keeps the lowest E of every frame.", min=0.0, max=1e6)
    ambiguous_px: float = setting(
        0.5, "With candidates > 1: a frame is ambiguous when another candidate's E per "
        "marker image is within this many pixels of the chosen one's (and within half the "
        "typical E per marker image of the video) while its posture is far from it (more "
        "than ambiguous_deg on some axis).", min=0.0, max=1e6)
    confirm_runs: str = setting(
        "auto", "Re-run a frame (up to max_runs) until two of its runs put every model "
        "marker within ambiguous_move segment lengths of each other, the best run one of "
        "them: a search that found its minimum once may have been lucky. 'auto': for a body "
        "annealed in several partitions (many limbs), where runs land on different limb "
        "assignments, and for any body whose markers are matched in 3D (match); 'on'; 'off' "
        "(the paper).",
        choices=CONFIRM_MODES)
    ambiguous_move: float = setting(
        0.25, "With candidates > 1: a candidate that fits about as well makes a frame "
        "ambiguous only if it moves some model marker by more than this fraction of the "
        "body's median segment length; 0: any candidate ambiguous_deg away does (axes that "
        "barely move a marker then flag frames). Also how close two runs must put every "
        "marker to confirm each other (confirm_runs), and how far apart a held limb's "
        "runs must put it for the frame to be ambiguous (final_polish_px).", min=0.0,
        max=1e6)
    ambiguous_deg: float = setting(
        5.0, "With candidates > 1: candidates nearer than this on every axis (degrees, or "
        "length units for translations) are the same posture.", min=1e-6, max=360.0)
    error: ErrorOptions = field(default_factory=lambda: ErrorOptions(**BEST_ERROR), metadata={
        "doc": "The error function: the bounded bidirectional variant with a 10-px marker "
        "cap (default), or the paper's Eq. 5 or another variant.",
        "flatten": {"mode": "error"}})
    seed: int = setting(0, "Seed of the random streams; written into every result.",
                        min=0, max=2**62)
    match: str = setting(
        "auto", "Where unlabelled markers are matched to the model: 'views' — each "
        "projected model marker to its nearest detection in every view (Eq. 5, the paper); "
        "'3d' — the detections are first triangulated across the calibrated views into 3D "
        "points (a marker seen in at least 3 views; kinematics.observe.cloud), and each model "
        "marker "
        "is matched to its nearest 3D point, its distance read in pixels at that point, so "
        "every pixel setting keeps its meaning; 'auto' — with 3 or more views (with markers "
        "of several colours: 3 or more views of each colour) '3d' for a body annealed in "
        "several partitions (many limbs), where blobs of different limbs fuse in the images, "
        "and for a single chain whose views hold more than twice as many detections as it "
        "has marker images (median over the video: other limbs' markers) or whose markers "
        "are all triangulated in at least 95 % of the frames, else 'views' (markers often "
        "absent: a limb would fold onto the points left; docs/fitting.md, 'When the "
        "defaults match in 3D').",
        choices=MATCH_MODES)
    backend: str = setting(
        "auto", "Which kernel anneals: 'scalar' one run at a time, 'lanes' many runs at once "
        "in SIMD lanes (the same results to the last bit; faster on many frames), 'cuda' one "
        "run per thread of an NVIDIA GPU through numba (pip install \"videotrack[gpu]\"; "
        "the scalar kernel's arithmetic with its roundings fused by the GPU's compiler: the "
        "same fits to within rounding, not to the bit; docs/fitting.md, 'Backends'), 'auto' "
        "lanes where they are valid (unlabelled points, labelled 2D keypoints or 3D points, "
        "one partition, start 'mean') and there are at least 32 runs per thread (half-empty "
        "lanes still beat the scalar kernel), else scalar; 'auto' never takes the GPU, so a "
        "result file does not depend on the machine. 'cuda' is valid where the lanes are.",
        choices=BACKENDS)
    precision: str = setting(
        "float64", "What the lanes' generated kernels compute E in: 'float64' gives the "
        "scalar kernel's results to the last bit; 'float32' is faster, but its results only "
        "match to within float32 rounding (docs/fitting.md, 'Backends'; docs/benchmarks.md, "
        "'Lanes', has its accuracy table). The scalar kernel, the lanes' general loops and "
        "the kernels for labelled keypoints and 3D points always use float64.",
        choices=PRECISIONS)

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`KinematicsError` naming the first invalid field."""
        ints = {"n_end": 1, "n_l": 1, "n_tau": 1, "max_redraws": 0, "max_runs": 1,
                "segment_length": 1, "refine_steps": 0, "seed": 0, "partition_rounds": 1,
                "auto_sample": 3, "candidates": 1}
        for name, least in ints.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or (
                    value < least):
                raise KinematicsError(f"must be an integer >= {least}, got {value!r}",
                                      field=name)
        if self.seed >= 2**63:
            raise KinematicsError(f"must be below 2**63, got {self.seed}", field="seed")
        positive = ("tau0", "l0", "reanalysis_threshold", "refine_gate_px", "claim_gate_px",
                    "auto_floor_px")
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
        for name in ("root_gate_px", "final_polish_px"):
            g = getattr(self, name)
            if g is not None and not (_is_real(g) and g > 0):
                raise KinematicsError(f"must be None or a number > 0, got {g!r}",
                                      field=name)
        for name in ("auto_k", "path_weight", "ambiguous_px", "ambiguous_move"):
            value = getattr(self, name)
            if not _is_real(value) or not (math.isfinite(value) and value >= 0):
                raise KinematicsError(f"must be a finite number >= 0, got {value!r}",
                                      field=name)
        if not _is_real(self.ambiguous_deg) or not 0 < self.ambiguous_deg <= 360:
            raise KinematicsError(f"must be in (0, 360], got {self.ambiguous_deg!r}",
                                  field="ambiguous_deg")
        for name in ("start_samples", "max_unexplained"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(
                    value, int | np.integer) or value < 0):
                raise KinematicsError(f"must be None or an integer >= 0, got {value!r}",
                                      field=name)
        for f in _CHOICE_FIELDS:  # the allowed values are the fields' ``choices``
            value, choices = getattr(self, f.name), f.metadata["choices"]
            if value not in choices:
                raise KinematicsError(f"must be one of {', '.join(choices)}, got {value!r}",
                                      field=f.name)
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

    @classmethod
    def paper(cls, **overrides) -> AnnealParams:
        """The paper's settings (Table 1 and its note, Eq. 5, one answer per frame), with
        ``overrides``: they reproduce Table 2."""
        return cls(**{**PAPER, **overrides})

    @classmethod
    def profile(cls, name: str, **overrides) -> AnnealParams:
        """The settings of a profile (:data:`PROFILES`: 'best', the defaults, or 'paper')."""
        if name not in PROFILES:
            raise KinematicsError(f"must be one of {', '.join(PROFILES)}, got {name!r}",
                                  field="profile")
        return cls.paper(**overrides) if name == "paper" else cls(**overrides)

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


#: The fields of :class:`AnnealParams` with allowed values (metadata ``choices``: START_MODES,
#: THRESHOLD_MODES, ...), which :meth:`AnnealParams.validate` checks.
_CHOICE_FIELDS = tuple(f for f in fields(AnnealParams) if "choices" in f.metadata)

#: The error function of the defaults (bench/bench_temporal.py, docs/benchmarks.md).
BEST_ERROR = {"mode": "bounded", "cap_px": 10.0}

#: Profiles: 'best' (the defaults) and 'paper' (what differs from them in the paper's).
PROFILES = ("best", "paper")
PAPER = {"refine": False, "threshold_mode": "absolute", "candidates": 1, "match": "views",
         "max_runs": 5, "final_polish_px": None,
         "start_samples": 0, "confirm_runs": "off", "error": ErrorOptions(),
         "noise_floor_px": None}


def _is_real(value) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_)


