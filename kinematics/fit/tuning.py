"""The fitter's tuning constants, in one record, each with the reason for its value.

These are not settings a user chooses (those are :class:`kinematics.fit.settings.AnnealParams`):
they are the measured choices behind the path through time, tracking, matching and the
flags. The measurements that chose them are in ``docs/benchmarks.md``; the experiments that
led there are in the project's history. A :class:`~kinematics.fit.Fitter` reads the record
:data:`TUNING` holds when it is made (``Fitter(..., tuning=...)`` takes another).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Tuning:
    # -- matching and the start search
    #: start-search draws per joint for several partitions: the fly's best measured count
    default_start_samples: int = 64
    #: 'auto' matches one chain in 3D above this many detections per marker image (clutter)
    clutter_ratio: float = 2.0
    #: ... or where triangulated points cover its markers in this share of frames
    covered_share: float = 0.95
    #: frames triangulated at most to measure that share (spread over the video)
    match_sample: int = 256
    #: Levenberg-Marquardt steps of the final polish at most (it stops once converged)
    polish_steps: int = 50
    # -- the path through time
    #: a chosen change above this (squared histogram spreads) re-fits both frames
    redo_jump: float = 1.0
    #: ... or above this many times the window's median change ...
    redo_jump_ratio: float = 16.0
    #: ... which is at least this
    redo_jump_min: float = 0.02
    #: a jump left after re-fits flags frames only where a marker moves this x the typical
    jump_seen_ratio: float = 8.0
    #: ... or this x the typical next to a cut (a wrong sequence start jumps where it ends)
    edge_seen_ratio: float = 3.0
    #: a re-fit joins a frame's candidates within this E per marker image (px) of its best
    refit_keep_px: float = 1.0
    #: re-fits a frame keeps beyond its own candidates: unbounded they multiply along a window
    refit_candidates: int = 4
    #: part of the schedule a cold re-fit from a neighbour anneals: the fly's speed/accuracy
    refit_share: float = 0.1
    #: decided frames kept before a window: the cut rule looks 2 back
    cut_context: int = 2
    #: the path decides windows of 2 x this and keeps the first half (fixed lag)
    path_lag: int = 32
    #: a candidate whose smoothest path moves this much more is ruled out, not ambiguous
    ambiguous_movement: float = 0.5
    #: the least E difference per marker image (px) still "about as well"
    ambiguous_floor_px: float = 1e-3
    # -- start = "track"
    #: part of the schedule a tracked frame's cold anneal runs: kept every right fly frame
    track_share: float = 0.1
    #: a tracked E above this x the recent median is fitted in full (the track is lost)
    track_jump: float = 1.5
    #: frames kept for that median
    track_memory: int = 16
    #: ... plus this per marker image (px): on a clean video E is noise
    track_jump_px: float = 0.05
    #: a full fit, merge or re-track replaces a track only below this x its E
    track_prefer: float = 0.9
    #: a re-track gives up after this many frames it has not taken
    track_window: int = 8
    #: a tracked E below this x the recent median tracks back (a lost leg found again)
    track_drop: float = 1.0
    #: a tracked E above this x its neighbours' median (+ track_jump_px) is ambiguous
    track_spike: float = 1.3
    #: neighbours on either side for that median
    track_spike_half: int = 8
    #: a limb is taken from another fit where its markers lie this much closer (px/image)
    track_merge_px: float = 0.5
    # -- the misplaced-marker flag
    #: a worst residual this many robust SDs above its window's median ...
    misplaced_k: float = 5.0
    #: ... with unexplained detections this many robust SDs above theirs ...
    misplaced_unexplained_k: float = 2.0
    #: ... among the results this many frames on either side
    misplaced_half: int = 32
    # -- free roots that re-acquire (kinematics.fit.reacquire)
    #: frames held back: the stretch before a re-acquired frame that a wrong placement can
    #: have held and that is re-fitted from the new one (-1: free roots never re-acquire)
    reacquire_back: int = 96
    # -- the noise model and the set-up checks (kinematics.fit.noise, .setup_check)
    #: labelled keypoints off their label a frame may have: what this share of the sample
    #: frames have at most (a DLC-like file: 10 % of keypoints swapped or missing)
    noise_outlier_share: float = 0.9
    #: σ is the Rayleigh σ of this quantile of the sample's matched residuals (a real
    #: mouse's: median 55 % of right frames failed, 0.9 4 %, 0.95 0.5 %)
    noise_sigma_quantile: float = 0.9
    #: a frame with at most this share of its markers on a detection is ambiguous
    #: (unlabelled: a free mouse seen by 3 of 6 markers was placed 22 mm off, "ok")
    few_matched_share: float = 0.5
    #: a marker image beyond the gate (σ) from its detection is unmatched; the gate is at
    #: least this, wider as a frame has more images (noise.gate_k: 4 σ failed 6 % of a
    #: fly's right frames, 180 images, on noise alone)
    noise_gate_k: float = 4.0
    #: a right frame fails a test with about this probability: its matched residuals' χ²
    #: quantile, and the gate all its images fall within
    noise_p: float = 1e-3
    #: two views agree where this share more of the detections lie nearer the other's
    #: epipolar lines than chance puts them (a 70-ghost sweep: 0.07; swapped cameras: 0.00)
    agree_excess: float = 0.05
    #: ... or their median distance is below this (px): a right calibration's, within noise
    agree_floor_px: float = 1.0
    #: frames (spread over the video) the detection checks look at
    setup_sample: int = 64
    #: a view shows too few detections below this share of its markers (median frame)
    setup_detection_share: float = 0.25
    #: the residuals' core σ above detections' spacing / this: a nearest-detection match
    #: means nothing there (a 4-σ gate then reaches halfway to the next detection; the stick
    #: insect's chain on a locust: 6.2; a fly with fused markers: 11.3; a real mouse: 20)
    setup_spacing_sigmas: float = 8.0
    #: a frame is gross where a marker lies farther than claim_gate_px from every detection,
    #: no missing one excusing it; of labelled keypoints, more than this share (a keypoint
    #: may be mislabelled: a DLC-like file has one in most frames)
    setup_gross_share: float = 0.25
    #: the chain does not fit where more than this share of the sample is gross: a right
    #: set-up has right frames, even where a short schedule misses many (a test's: 47 of 64;
    #: views swapped: 60 of 60)
    setup_fail_share: float = 0.9


#: The record every fitter takes unless it is given another.
TUNING = Tuning()
