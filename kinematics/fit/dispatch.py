"""Which kernel fits a block of frames (scalar, lanes, CUDA), the inputs each takes, and
the partitions and error arguments they share.
"""

from __future__ import annotations

import os
import warnings

import numba
import numpy as np

from kinematics._kernels import codes as _codes
from kinematics._kernels import cuda as _ck
from kinematics._kernels import frames as _frames
from kinematics._kernels import lane_codegen as _codegen
from kinematics._kernels import lanes as _lk
from kinematics._kernels import objective as _objective
from kinematics._kernels.records import FrameObs
from kinematics.cameras import CameraArrays
from kinematics.errors import KinematicsError
from kinematics.fit.partitions import partitions_of
from kinematics.fit.problem import ErrorArgs, FitOutputs, error_args, schedule_of
from kinematics.fit.result import FrameResult
from kinematics.fit.settings import AnnealParams
from kinematics.observe.observations import ObservationArrays, Observations


class DispatchMixin:
    """The :class:`~kinematics.fit.Fitter`'s kernel dispatch."""

    def _limbs(self, p: AnnealParams) -> bool:
        """Whether the body is annealed in several partitions (many limbs)."""
        return self._partitions(p, search=False).bounds.shape[0] > 1

    def _partitions(self, p: AnnealParams, search: bool = True, cloud: bool = False):
        """The fit's partitions; the start search as ``start_samples`` says (None: 64 for
        several partitions, none for one) and runs confirmed as ``confirm_runs`` says
        ('auto': for several partitions, or markers matched in 3D, ``cloud``), or neither
        (``search`` False: a re-fit from a neighbour's posture)."""
        parts = self._once(  # the re-fits ask for them hundreds of times per block
            ("partitions", p.partitions, p.partition_rounds, p.claim_gate_px),
            lambda: partitions_of(self.problem, p.partitions, p.partition_rounds,
                                  p.claim_gate_px))
        samples = p.start_samples
        if samples is None:
            samples = self.tuning.default_start_samples if parts.bounds.shape[0] > 1 else 0
        confirm = p.confirm_runs == "on" or (p.confirm_runs == "auto" and (
            parts.bounds.shape[0] > 1 or cloud))
        return parts._replace(samples=int(samples) if search else 0,
                              confirm=float(self._apart(p))
                              if confirm and search else 0.0)

    def _fit_block(self, obs: Observations, sel, frame_ids, roots, rots, start, seg_off,
                   params: AnnealParams | None = None) -> list[FrameResult]:
        """Fit frames ``sel`` of ``obs`` (``frame_ids`` key their random streams)."""
        p, pr = params or self.params, self.problem
        block = obs.arrays(sel)
        cams, arrays = self._kernel_inputs(block)
        n, ns, nv = len(frame_ids), pr.n_state, len(cams.kind)
        out = FitOutputs.empty(n, ns, nv, max(p.max_runs, p.candidates))
        parts = self._partitions(p, cloud=obs.kind == "cloud")
        backend = self._backend(p, arrays.objective, parts, n,
                                hidden=obs.hidden is not None or obs.unseen is not None)
        if backend == "cuda":
            try:
                _ck.fit_frames_rounds(frame_ids, roots, rots, start, pr.folded, pr.cams,
                                      pr.dofs, schedule_of(p),
                                      self._error_args(p, arrays.objective), arrays,
                                      float(p.claim_gate_px), out)
            except _ck.GpuFailed as exc:
                raise KinematicsError(f"the cuda backend failed: {exc}; use backend 'auto'",
                                      field="backend") from exc
        elif backend == "lanes":
            threads = numba.get_num_threads()
            groups = np.unique(np.linspace(0, n, min(threads, n) + 1).astype(np.int64))
            error = self._error_args(p, arrays.objective)
            # labelled keypoints and 3D points have no float32 kernel: theirs stays float64
            single = p.precision == "float32" and arrays.objective == _codes.OBJ_NEAREST
            fused, n_fused = self._fused_kernel(arrays, error, single)
            _lk.fit_frames_lanes(groups, frame_ids, roots, rots, start, pr.folded, pr.cams,
                                 pr.dofs, schedule_of(p), error, arrays,
                                 float(p.claim_gate_px), fused, (_lk.LANES, n_fused, single),
                                 out)
        else:
            _frames.fit_frames(seg_off, frame_ids, roots, rots, start, pr.folded, cams,
                           pr.dofs, schedule_of(p), self._error_args(p, arrays.objective),
                           arrays, parts, out)
        view_error = out.view_error if nv == self.n_views else np.zeros((n, self.n_views))
        batch = self._block_residuals(obs, block, out, roots, rots, float(p.claim_gate_px))
        results = []
        for k in range(n):
            cands = ()
            if p.candidates > 1 and out.runs[k]:
                cands = self._candidates(out.run_angles[k], out.run_error[k], roots[k],
                                         rots[k], p)
            results.append(self._frame_result(
                obs, int(sel[k]), int(frame_ids[k]), out.angles[k], roots[k], rots[k], p,
                arrays=block.frame(k, obs.n_views),
                runs=int(out.runs[k]), iterations=int(out.iterations[k]),
                pairs=int(out.pairs[k]), error=(float(out.error[k]), view_error[k].copy()),
                candidates=cands, given_residuals=None if batch is None else (
                    batch[0][k], int(batch[1][k])),
                confirmed_only=parts.confirm > 0 and bool(
                    np.nanmin(out.run_error[k, :max(1, p.candidates)], initial=np.inf)
                    <= p.reanalysis_threshold)))
        return results

    def _block_residuals(self, obs: Observations, block: ObservationArrays, out, roots, rots,
                         gate: float):
        """(marker residuals (n, n_views, n_markers), unexplained (n,)) of a block's fitted
        frames, as :meth:`_residuals` gives them frame by frame, in one kernel call; None
        where its per-frame rules apply (keypoints, 3D points, clouds, no views, hidden
        markers, views that show only some markers)."""
        if (obs.kind != "points" or not obs.n_views or obs.hidden is not None
                or obs.unseen is not None or self.unseen is not None):
            return None
        n, pr = len(out.runs), self.problem
        res = np.full((n, self.n_views, pr.folded.marker_joint.size), np.nan)
        unexplained = np.zeros(n, np.int64)
        _objective.block_residuals(out.angles, out.runs > 0, roots, rots, pr.folded, pr.cams,
                            block.points, block.offsets, gate, res, unexplained)
        return res, unexplained

    def _kernel_inputs(self, arrays: ObservationArrays):
        """Cameras and observations as ``fit_frames`` takes them: for a 3D objective (a
        cloud) without the views, whose projections such a fit never reads (they were most
        of an iteration's cost with six pinhole cameras)."""
        if arrays.objective != _codes.OBJ_CLOUD:
            return self.problem.cams, arrays
        cams = CameraArrays(*(np.ascontiguousarray(a[:0]) for a in self.problem.cams))
        return cams, arrays._replace(points=np.empty((0, 2)), conf=np.empty(0),
                                     offsets=np.zeros(1, np.int64))

    def _fused_kernel(self, arrays: ObservationArrays, error: ErrorArgs,
                      single: bool = False):
        """The lane kernel generated for this body, its views and the block's detections
        per view (:mod:`kinematics._kernels.lane_codegen`) and the detections it scans; the general
        loops (``no_fused``, 0) where none is made: for a body too large or a view of the
        block with too many detections, with ``VIDEOTRACK_NO_CODEGEN`` set, or where the
        kernel cannot be made (a read-only cache folder: a warning, the same results).
        ``single``: a kernel computing in float32 (precision 'float32'; unlabelled points
        only, as :meth:`_fit_block` asks)."""
        # labelled keypoints and 3D points: point i is marker i's, no scan
        labelled = arrays.objective == _codes.OBJ_LABELLED
        points3d = arrays.objective == _codes.OBJ_POINTS3D
        counts = np.diff(arrays.offsets)
        c_cap = 0 if labelled or points3d else int(counts.max()) if counts.size else 0
        if (arrays.objective not in (_codes.OBJ_NEAREST, _codes.OBJ_LABELLED, _codes.OBJ_POINTS3D)
                or os.environ.get("VIDEOTRACK_NO_CODEGEN")
                or not _codegen.fits(self.problem.folded, self.problem.cams, c_cap,
                                     points3d)):
            return _lk.no_fused, 0
        try:
            fn = _codegen.fused_kernel(self.problem.folded, self.problem.cams, c_cap,
                                       (error.bidirectional, error.weight, error.cap,
                                        error.penalty_cap),
                                       single=single, labelled=labelled,
                                       points3d=points3d)
        except Exception as exc:  # any failure: the general loops give the same results
            warnings.warn(f"lanes: no kernel generated for this body ({exc}); using the "
                          "general loops (the same results, slower)", stacklevel=2)
            return _lk.no_fused, 0
        return fn, _codegen.padded_detections(c_cap)

    def lane_frames(self) -> int:
        """Frames whose runs fill the lanes of every numba thread once, or with backend
        'cuda' half a GPU launch (:data:`kinematics._kernels.cuda.GPU_RUNS`); ``iter_fit``
        fits blocks of twice this, the pipeline hands the fitting thread four times."""
        runs = _ck.GPU_RUNS if self.params.backend == "cuda" else (
            _lk.LANES * numba.get_num_threads())
        return -(-runs // max(1, self.params.candidates))

    @staticmethod
    def _backend(p: AnnealParams, objective: int, parts, n_frames: int, *,
                 hidden: bool = False) -> str:
        """Which kernel fits this block: 'lanes' or 'cuda' where they do what the scalar
        kernel does — unlabelled points, labelled 2D keypoints or 3D points, one partition
        and independent frames, without markers marked hidden (``hidden``) — else 'scalar'.
        'auto' also wants a few runs per thread for the lanes
        (:data:`kinematics._kernels.lanes.MIN_RUNS_PER_THREAD`: a single frame, as the GUI
        fits, goes to the scalar kernel), and never takes the GPU: its results equal the
        scalar kernel's to within rounding only, and a result file should not depend on
        the machine (docs/fitting.md, 'Reproducibility')."""
        valid = (objective in (_codes.OBJ_NEAREST, _codes.OBJ_LABELLED, _codes.OBJ_POINTS3D)
                 and parts.bounds.shape[0] == 1
                 and parts.samples == 0 and p.start == "mean" and not p.error.one_to_one
                 and parts.confirm == 0 and not hidden)
        if p.backend in ("lanes", "cuda") and not valid:
            raise KinematicsError(f"the {p.backend} backend fits unlabelled points, labelled "
                                  "2D keypoints or 3D points with one partition, start "
                                  "'mean', no start samples and no hidden markers (nor "
                                  "views that show only some: [[views]] model_markers); use "
                                  "backend 'auto' or 'scalar'",
                                  field="backend")
        if p.backend == "cuda":
            if not _ck.available():
                raise KinematicsError("the cuda backend needs an NVIDIA GPU that numba can "
                                      "use (numba.cuda.is_available() is False here; pip "
                                      "install \"videotrack[gpu]\"); use backend 'auto'",
                                      field="backend")
            return "cuda"
        runs = n_frames * max(1, p.candidates)
        lanes = p.backend == "lanes" or (p.backend == "auto" and valid
                                         and runs >= _lk.MIN_RUNS_PER_THREAD
                                         * numba.get_num_threads())
        return "lanes" if lanes else "scalar"

    def _state_error(self, arrays, state, root_pos, root_rot, p: AnnealParams):
        """(E, E per view) of a kernel state for one frame's observation arrays."""
        per_view = np.empty(self.n_views)
        obs3 = (arrays.points3d[0] if arrays.points3d.shape[1]
                else np.zeros((self.problem.folded.marker_joint.size, 4)))
        e = _objective.posture_error(
            np.ascontiguousarray(state), root_pos, root_rot, self.problem.folded,
            self.problem.cams, FrameObs(arrays.objective, arrays.points, arrays.conf,
                                        arrays.offsets, obs3),
            self._error_args(p, arrays.objective), per_view)
        return float(e), per_view

    def _error_args(self, p: AnnealParams, objective: int) -> ErrorArgs:
        """The error function's numbers for the kernels. Matching in 3D a marker counts once,
        not once per view, so its caps are the views' together: with the per-view 10-px cap
        a cloud point 0.1 mm away at 100 px/mm already cost the most, and a far limb had no
        slope to follow (the fly with the defaults: 3 % of frames right, 45 % with this)."""
        args = error_args(p.error)
        if objective == _codes.OBJ_CLOUD:
            views = self.n_views if self.unseen is None else int(
                (~self.unseen).sum(axis=0).max())  # the views that show a marker
            return args._replace(cap=args.cap * views, penalty_cap=args.penalty_cap * views)
        return args
