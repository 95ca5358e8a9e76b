"""Set-up checks: a wrong set-up refused before hours of fitting, not reported as "done, 0 %
bad".

Two kinds. Before any fit, on the detections of frames spread over the video
(:func:`detection_problems`): views that show almost no detections (a video without markers,
filters that find nothing), and views that disagree in 3D (a mis-scaled or swapped camera,
swapped views: :func:`kinematics.observe.agreement.view_agreement`). After the first frames
are fitted (:func:`fit_problems`): a chain that does not fit the detections — at best its
markers lie farther from them than a nearest-detection match can mean (σ against the
detections' spacing), or most frames fail the noise test (:mod:`kinematics.fit.noise`).

Each problem is one line naming its cause. :class:`SetupError` refuses the fit with them,
unless ``AnnealParams.accept_setup`` (then they are warnings of the results).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from kinematics.errors import KinematicsError
from kinematics.fit.noise import Verdict
from kinematics.fit.tuning import Tuning
from kinematics.observe.agreement import view_agreement
from kinematics.observe.observations import Observations

#: How a user fits anyway, said with every refusal.
ACCEPT_HINT = ("if the set-up is right, set [anneal] accept_setup = true (fit and run: "
               "--accept-setup) to fit anyway")


class SetupError(KinematicsError):
    """The set-up (cameras, views, chain, video) does not fit the detections."""


def refuse(problems: Sequence[str]) -> None:
    """Raise :class:`SetupError` with the first problem (and how many more) in one line."""
    more = f" (and {len(problems) - 1} more problem(s))" if len(problems) > 1 else ""
    raise SetupError(f"set-up check: {problems[0]}{more}; {ACCEPT_HINT}")


def sample_frames(obs: Observations, count: int) -> np.ndarray:
    """Up to ``count`` frames with detections, spread evenly over the video."""
    seen = np.flatnonzero(obs.view_counts(np.arange(obs.n_frames)).sum(axis=1) > 0)
    if seen.size <= count:
        return seen
    return seen[np.unique(np.linspace(0, seen.size - 1, count).astype(int))]


def detection_problems(obs: Observations, cameras, view_names: Sequence[str],
                       shown_views: np.ndarray, tuning: Tuning) -> list[str]:
    """What is wrong with the detections before any fit: views that show too few of their
    markers (``shown_views``: (n_views, n_markers) bool, the markers each view shows) in the
    median frame, views whose detections agree in 3D with no other view's through the
    cameras (:func:`~kinematics.observe.agreement.view_agreement`; a view of other markers is
    not compared). Unlabelled and labelled 2D detections only (3D points have no views to
    compare)."""
    shown = shown_views.sum(axis=1)
    if obs.kind not in ("points", "keypoints") or obs.n_frames == 0:
        return []
    everything = np.arange(obs.n_frames)
    counts = obs.view_counts(everything)
    if not counts.any():
        return [f"no detections in any view of the {obs.n_frames} frames (a video without "
                "markers? check the video and the [filters] and [markers] settings)"]
    out = []
    median = np.median(counts, axis=0)
    few = [v for v in range(obs.n_views)
           if median[v] < max(1.0, tuning.setup_detection_share * shown[v])]
    if len(few) * 2 > obs.n_views:  # most views: the video, or its filters (one is blocked)
        said = ", ".join(f"{view_names[v]} {median[v]:g}" for v in few)
        out.append(f"too few detections: the median frame shows {said} where the chain has "
                   f"{int(max(shown))} markers (a video without markers? check the [filters] "
                   "and [markers] settings)")
    if cameras is None or obs.n_views < 2:
        return out
    pairs = view_agreement(cameras, obs, sample_frames(obs, tuning.setup_sample), shown_views)
    agree = [p.distance_px <= tuning.agree_floor_px or p.excess >= tuning.agree_excess
             for p in pairs]
    measured = {v for p in pairs for v in (p.a, p.b)}
    fine = {v for p, ok in zip(pairs, agree, strict=True) if ok for v in (p.a, p.b)}
    alone = sorted(measured - fine)  # views that agree with no other view
    if alone:
        best = {v: min((p for p in pairs if v in (p.a, p.b)), key=lambda p: p.distance_px)
                for v in alone}
        said = "; ".join(
            f"{view_names[v]!r}: {best[v].distance_px:.1f} px from the epipolar lines of "
            f"{view_names[best[v].b if best[v].a == v else best[v].a]!r}, "
            f"{best[v].chance_px:.1f} px by chance" for v in alone)
        what = "views" if len(alone) > 1 else "view"
        out.append(f"{what} {', '.join(repr(view_names[v]) for v in alone)} disagree"
                   f"{'s' if len(alone) == 1 else ''} in 3D with every other view ({said}): "
                   "a wrong camera file, cameras or views swapped, or views' regions that do "
                   "not match the cameras")
    return out


def detection_spacing(obs: Observations, frames: np.ndarray) -> np.ndarray:
    """Per view, the median distance from a detection to its nearest neighbour in the same
    view (px) over ``frames``; NaN where no frame shows two."""
    gaps: list[list[float]] = [[] for _ in range(obs.n_views)]
    for f in frames:
        for v, pts in enumerate(obs.frame_views(int(f))):
            pts = np.asarray(pts, float)
            pts = pts[np.isfinite(pts).all(axis=1)]
            if len(pts) > 1:
                d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
                np.fill_diagonal(d, np.inf)
                gaps[v].append(float(np.median(d.min(axis=1))))
    return np.array([np.median(g) if g else np.nan for g in gaps])


def fit_problems(view_names: Sequence[str], sigma: np.ndarray, spacing: np.ndarray,
                 verdicts: Sequence[Verdict], tuning: Tuning, labelled: bool = False
                 ) -> list[str]:
    """What fitted frames say of the set-up (a sample of frames fitted once, or the first
    frames tracked): σ (of the residuals' core, their median) so large against the
    detections' ``spacing`` that matching markers to
    their nearest detection means nothing, or more than ``Tuning.setup_fail_share`` of them
    gross: a marker far from every detection (``Verdict.gross``) where none is missing (of
    ``labelled`` keypoints, more than ``Tuning.setup_gross_share`` of them)."""
    out = []
    wide = [v for v in range(len(sigma))
            if np.isfinite(spacing[v]) and sigma[v] > spacing[v] / tuning.setup_spacing_sigmas]
    if wide:
        said = ", ".join(f"{view_names[v]} {sigma[v]:.2f} px where detections lie "
                         f"{spacing[v]:.1f} px apart" for v in wide)
        out.append(f"the chain does not fit the detections: at best its markers lie far from "
                   f"them ({said}; a chain of another animal or scale, or wrong cameras)")
    share = tuning.setup_gross_share if labelled else 0.0
    failing = sum(v.gross > share * v.measured for v in verdicts)
    if verdicts and failing > tuning.setup_fail_share * len(verdicts):
        far = int(np.median([v.gross for v in verdicts]))
        out.append(f"the chain does not fit the detections: in {failing} of "
                   f"{len(verdicts)} sample frames fitted markers lie far from every "
                   f"detection (typically {far} marker image(s)) where no detection is "
                   "missing: a chain of another animal or scale, wrong cameras or views, or "
                   "a video whose blobs are not the markers")
    return out
