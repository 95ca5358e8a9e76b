"""CUDA backend: one annealing run per GPU thread (private; the public entry is
:class:`kinematics.fit.Fitter` with ``backend = "cuda"``).

The GPU runs the scalar kernel itself: every thread calls
:func:`kinematics._kernels.anneal.anneal_chain` (numba compiles it as a device function),
with its scratch in the thread's local memory, on the random stream of its (seed, frame,
run). There is no GPU twin to keep in step: the arithmetic is the scalar kernel's. NVVM
fuses multiplies and adds (numba gives no switch to stop it), so a run's roundings differ
from the CPU's in the last bit and its result equals the scalar kernel's to within
rounding, unless an acceptance decision flips on one (tests/kinematics/test_cuda.py on a
GPU; ``bench/bench_cuda.py``).

The frame procedure (refinement, the re-analysis runs a frame's E asks for, the kept run)
stays on the CPU, in rounds: every waiting run of every frame anneals in one launch, then
the CPU finishes them (:func:`finish_tasks`, in parallel) and decides which frames want
another run (:func:`next_tasks`) — the runs and the kept run of the scalar ``fit_frames``,
taken in the same order. With the kernel's CPU twin (:func:`anneal_tasks_cpu`) the rounds
give ``fit_frames``' outputs to the last bit, which the tests check without a GPU. Valid
for the problems the lanes take (``Fitter._backend``: independent frames, one partition,
start 'mean').
"""

from __future__ import annotations

import functools
import threading
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from kinematics._kernels.anneal import anneal_chain
from kinematics._kernels.fastmath import stream_state
from kinematics._kernels.frames import clear_frame, finish_run, take_runs, wants_run, write_frame
from kinematics._kernels.objective import observed
from kinematics._kernels.records import Scratch, frame_obs, new_scratch

#: Threads per block of the annealing kernel (each thread one run).
THREADS = 128

#: Half the runs of a launch (``Fitter.lane_frames``; ``iter_fit`` fits blocks of twice
#: this). The locust's paper protocol on an H100 (bench/bench_cuda.py): one launch of
#: 16 384 runs 11 500 frames/s, launches of 32 768 runs 15 800.
GPU_RUNS = 16384

class Tasks(NamedTuple):
    """A round's runs: task r anneals run ``run[r]`` of frame ``frame[r]``."""

    frame: np.ndarray  # (n_tasks,) int64
    run: np.ndarray  # (n_tasks,) int64


class RunInputs(NamedTuple):
    """What every task reads (the arguments of ``fit_frames`` it needs; on the GPU, device
    arrays)."""

    frame_ids: np.ndarray
    root_pos: np.ndarray
    root_rot: np.ndarray
    start: np.ndarray
    body: tuple  # FoldedBody
    cams: tuple  # CameraArrays
    dofs: tuple  # DofArrays
    schedule: tuple  # Schedule
    error: tuple  # ErrorArgs
    obs: tuple  # ObservationArrays
    claimed: np.ndarray  # no claims: all false


class RunOutputs(NamedTuple):
    """Each task's annealed posture, its E and its iterations."""

    best: np.ndarray  # (n_tasks, n_state)
    e: np.ndarray  # (n_tasks,)
    iterations: np.ndarray  # (n_tasks,) int64


class GpuFailed(RuntimeError):
    """The GPU could not compile or run the kernel (the reason in the message)."""


_lock = threading.Lock()
_kernels: dict[tuple, object] = {}


@functools.cache
def available() -> bool:
    """Whether numba sees a CUDA GPU; False where numba's CUDA target cannot even be
    imported (numba.cuda is imported here, on first use: 80 ms most fits need not wait),
    and under numba's CUDA simulator, which cannot call the CPU-compiled kernel. Asked once
    per process."""
    try:
        from numba import config, cuda
        return bool(cuda.is_available()) and not config.ENABLE_CUDASIM
    except Exception:  # no CUDA toolkit or driver: numba raises many kinds
        return False


@njit(cache=True, nogil=True)
def run_task(r, tasks, inputs, outs, scratch):
    """Task ``r``'s run (frame ``tasks.frame[r]``, run ``tasks.run[r]``) annealed from
    ``inputs.start`` into ``outs.best[r]``, ``outs.e[r]``, ``outs.iterations[r]``: what one
    GPU thread does, and its CPU twin (:func:`anneal_tasks_cpu`) per task."""
    f = tasks.frame[r]
    schedule, body = inputs.schedule, inputs.body
    nv = inputs.cams.kind.shape[0]
    counts = (schedule.n_end, schedule.n_l, schedule.n_tau)
    e, its = anneal_chain(
        inputs.start, inputs.dofs.free_idx, counts,
        stream_state(schedule.seed, inputs.frame_ids[f], tasks.run[r]), inputs.root_pos[f],
        inputs.root_rot[f], body, inputs.cams, inputs.dofs, schedule, inputs.error,
        frame_obs(inputs.obs, f, nv), (0, body.parent.shape[0], 0, body.marker_joint.shape[0]),
        inputs.claimed, scratch,
        scratch.per_view[:0])  # no cloud on the GPU: no scratch for cloud_error_once
    for k in range(inputs.start.shape[0]):
        outs.best[r, k] = scratch.best[k]
    outs.e[r] = e
    outs.iterations[r] = its


@njit(cache=True, nogil=True, parallel=True)
def anneal_tasks_cpu(tasks, frame_ids, root_pos, root_rot, start, body, cams, dofs, schedule,
                     error, obs, claimed, outs):
    """:func:`run_task` for every task on the CPU's threads, each with its own scratch: the
    GPU kernel's twin (the rounds' test oracle). The fields of :class:`RunInputs` come one
    by one: numba's parallel loop takes flat records only, so it is rebuilt per task."""
    na, nv = start.shape[0], cams.kind.shape[0]
    nj, nm = body.parent.shape[0], body.marker_joint.shape[0]
    for r in prange(tasks.frame.shape[0]):
        run_task(r, tasks, _run_inputs(frame_ids, root_pos, root_rot, start, body, cams, dofs,
                                       schedule, error, obs, claimed), outs,
                 new_scratch(na, nj, nm, nv))


@njit(cache=True, nogil=True)
def _run_inputs(frame_ids, root_pos, root_rot, start, body, cams, dofs, schedule, error, obs,
                claimed):
    """A :class:`RunInputs` built in a function of its own (a parallel loop's body cannot
    build a namedtuple)."""
    return RunInputs(frame_ids, root_pos, root_rot, start, body, cams, dofs, schedule, error,
                     obs, claimed)


def _kernel(na: int, nj: int, nm: int, nv: int):
    """The GPU kernel for ``na`` state entries, ``nj`` joints, ``nm`` markers and ``nv``
    views (the sizes of each thread's scratch, in its local memory): :func:`run_task` per
    thread. Compiled on its first launch, once per process and shape; ``fastmath`` off
    (IEEE division and square root, no flushing of subnormals)."""
    key = (na, nj, nm, nv)
    with _lock:
        if key in _kernels:
            return _kernels[key]
        from numba import cuda, float64, int64
        na1, nm1, nv1 = max(na, 1), max(nm, 1), max(nv, 1)

        def anneal_tasks(tasks, inputs, outs):
            # the scratch in the thread's local memory (shapes are compile-time constants)
            r = cuda.grid(1)
            if r < tasks.frame.shape[0]:
                scratch = Scratch(
                    cuda.local.array(na1, float64)[:na], cuda.local.array(na1, float64)[:na],
                    cuda.local.array(na1, float64)[:na], cuda.local.array(na1, float64)[:na],
                    cuda.local.array(na1, float64)[:na],
                    cuda.local.array((nj, 3, 3), float64), cuda.local.array((nj, 3), float64),
                    cuda.local.array((nm1, 3), float64)[:nm],
                    cuda.local.array((nv1, nm1, 2), float64)[:nv, :nm],
                    cuda.local.array(nv1, float64)[:nv], cuda.local.array(nm1, int64)[:nm])
                run_task(r, tasks, inputs, outs, scratch)

        _kernels[key] = cuda.jit(fastmath=False)(anneal_tasks)
        return _kernels[key]


# -- the frame procedure, on the CPU --------------------------------------------------------
@njit(cache=True, nogil=True)
def first_tasks(objective, det_off, obs3, nv, first_runs, out):
    """Clear every frame's outputs; the first ``first_runs`` runs of every frame with
    observations, as (frames, runs)."""
    n = out.runs.shape[0]
    frames = np.empty(n * first_runs, np.int64)
    runs = np.empty(n * first_runs, np.int64)
    k = 0
    for f in range(n):
        clear_frame(out, f)
        if observed(objective, det_off[f * nv: f * nv + nv + 1], obs3[f]):
            for r in range(first_runs):
                frames[k] = f
                runs[k] = r
                k += 1
    return frames[:k], runs[:k]


@njit(cache=True, nogil=True, parallel=True)
def finish_tasks(task_frame, task_run, best, e, root_pos, root_rot, body, cams, dofs,
                 schedule, error, obs, claim_gate, out, run_u, run_pairs):
    """Refine and score each annealed run (``finish_run``, in parallel) into the frame's run
    outputs."""
    nv = cams.kind.shape[0]
    nj = body.parent.shape[0]
    nm = body.marker_joint.shape[0]
    na = best.shape[1]
    # the arrays taken out of the namedtuple first: stores through ``out.run_angles`` in a
    # prange were lost
    run_angles, run_error = out.run_angles, out.run_error
    for r in prange(task_frame.shape[0]):
        f = task_frame[r]
        run = task_run[r]
        state = best[r].copy()
        e_run, pairs, u = finish_run(state, e[r], root_pos[f], root_rot[f], body, cams, dofs,
                                     schedule, error, frame_obs(obs, f, nv), claim_gate,
                                     np.empty(na), new_scratch(na, nj, nm, nv))
        run_angles[f, run, :] = state
        run_error[f, run] = e_run
        run_u[f, run] = u
        run_pairs[f, run] = pairs


@njit(cache=True, nogil=True)
def next_tasks(task_frame, task_run, its, root_pos, root_rot, body, cams, schedule, error,
               obs, out, run_u, run_pairs):
    """After a round: each frame's runs so far taken in run order (the kept run, as the
    scalar kernel keeps it), then the frame's next run if its E asks for one, else its
    outputs. Returns the next round's (frames, runs); a frame's tasks are consecutive."""
    min_runs, max_runs = schedule.min_runs, schedule.max_runs
    threshold, max_unexplained = schedule.reanalysis_threshold, schedule.max_unexplained
    nv = cams.kind.shape[0]
    nj = body.parent.shape[0]
    nm = body.marker_joint.shape[0]
    na = out.angles.shape[1]
    keep = np.empty(na)
    scratch = new_scratch(na, nj, nm, nv)
    n_tasks = task_frame.shape[0]
    frames = np.empty(n_tasks, np.int64)
    runs = np.empty(n_tasks, np.int64)
    k = 0
    for r in range(n_tasks):
        f = task_frame[r]
        out.iterations[f] += its[r]
        if r + 1 < n_tasks and task_frame[r + 1] == f:
            continue  # the frame's last task of the round decides
        issued = task_run[r] + 1
        e_keep, u_keep, kept = take_runs(out, f, issued, run_u[f], run_pairs[f],
                                         max_unexplained)
        if wants_run(issued, min_runs, max_runs, e_keep, u_keep, threshold, max_unexplained):
            frames[k] = f
            runs[k] = issued
            k += 1
        else:
            keep[:] = out.run_angles[f, kept, :]
            write_frame(out, f, keep, issued, root_pos[f], root_rot[f], body, cams, error,
                        frame_obs(obs, f, nv), scratch)
    return frames[:k], runs[:k]


def fit_frames_rounds(frame_ids, root_pos, root_rot, start, body, cams, dofs, schedule,
                      error, obs, claim_gate, out, gpu=True):
    """The scalar ``fit_frames`` for independent frames (one partition, every run from
    ``start``; the same arguments and outputs), each round's runs annealed at once: on the
    GPU, or with ``gpu`` false by the kernel's CPU twin."""
    nv = cams.kind.shape[0]
    na, nj, nm = start.shape[0], body.parent.shape[0], body.marker_joint.shape[0]
    first = min(max(schedule.min_runs, 1), schedule.max_runs)
    frames, runs = first_tasks(obs.objective, obs.offsets, obs.points3d, nv, first, out)
    if not frames.size:
        return
    n = out.runs.shape[0]
    run_u = np.zeros((n, schedule.max_runs), np.int64)
    run_pairs = np.zeros((n, schedule.max_runs), np.int64)
    inputs = RunInputs(frame_ids, np.ascontiguousarray(root_pos), np.ascontiguousarray(root_rot),
                       start, body, cams, dofs, schedule, error, obs,
                       np.zeros(max(obs.points.shape[0], obs.points3d.shape[1], 1), np.bool_))
    if gpu:
        inputs = _on_gpu(inputs)
    while frames.size:
        t = frames.size
        outs = RunOutputs(np.empty((t, na)), np.empty(t), np.empty(t, np.int64))
        if gpu:
            _launch(_kernel(na, nj, nm, nv), Tasks(frames, runs), inputs, outs)
        else:
            anneal_tasks_cpu(Tasks(frames, runs), *inputs, outs)
        finish_tasks(frames, runs, outs.best, outs.e, root_pos, root_rot, body, cams, dofs,
                     schedule, error, obs, claim_gate, out, run_u, run_pairs)
        frames, runs = next_tasks(frames, runs, outs.iterations, root_pos, root_rot, body, cams,
                                  schedule, error, obs, out, run_u, run_pairs)


def _reason(what: str, exc: Exception) -> GpuFailed:
    """A :class:`GpuFailed` of one line: numba's CUDA errors span many lines (a typing
    error lists every candidate), so only the first line of the message is kept."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return GpuFailed(f"{what} ({type(exc).__name__}: {lines[0] if lines else 'no message'})")


def _on_gpu(record):
    """The record with every array in it (records nested) copied to the GPU."""
    from numba import cuda
    try:
        return _mapped(record, cuda.to_device)
    except Exception as exc:  # numba raises many kinds; the reason is in the message
        raise _reason("copying to the GPU failed", exc) from exc


def _mapped(record, to_device):
    if isinstance(record, np.ndarray):
        return to_device(record)
    if isinstance(record, tuple):
        values = [_mapped(v, to_device) for v in record]
        return type(record)(*values) if hasattr(record, "_fields") else tuple(values)
    return record


def _launch(kernel, tasks, inputs, outs) -> None:
    """One launch of ``kernel`` over ``tasks``; its outputs into ``outs``."""
    from numba import cuda
    try:
        d_outs = RunOutputs(*(cuda.device_array_like(a) for a in outs))
        kernel[-(-tasks.frame.size // THREADS), THREADS](_on_gpu(tasks), inputs, d_outs)
        for d, a in zip(d_outs, outs, strict=True):
            d.copy_to_host(a)
    except Exception as exc:  # compiling (the first launch) or running
        raise _reason("the GPU kernel failed", exc) from exc
