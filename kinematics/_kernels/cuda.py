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
import inspect
import threading

import numpy as np
from numba import njit, prange

from kinematics._kernels.anneal import anneal_chain
from kinematics._kernels.fastmath import stream_state
from kinematics._kernels.frames import clear_frame, finish_run, take_runs, wants_run, write_frame
from kinematics._kernels.objective import observed

#: Threads per block of the annealing kernel (each thread one run).
THREADS = 128

#: Half the runs of a launch (``Fitter.lane_frames``; ``iter_fit`` fits blocks of twice
#: this). The locust's paper protocol on an H100 (bench/bench_cuda.py): one launch of
#: 16 384 runs 11 500 frames/s, launches of 32 768 runs 15 800.
GPU_RUNS = 16384

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
def run_task(r, task_frame, task_run, frame_ids, root_pos, root_rot, start, free_idx, step,
             hist, nbins, dof_kind, lo, hi, max_redraws, n_end, n_l, n_tau, th, tau0, l0, c_l,
             c_tau, eps, seed, parent, chain, pre_rot, pre_trans, post_trans, elem_axis,
             elem_index, joint_flags, marker_joint, marker_local, slide_index, kind, P, K,
             dist, R, t, objective, points, conf, det_off, obs3, bidirectional, weight, cap,
             penalty_cap, claimed, best_out, e_out, it_out, cur, cand, best, cs, sn, rot, pos,
             mk, proj, per_view, nearest):
    """Task ``r``'s run (frame ``task_frame[r]``, run ``task_run[r]``) annealed from
    ``start`` into ``best_out[r]``, ``e_out[r]``, ``it_out[r]``: what one GPU thread does,
    and its CPU twin (:func:`anneal_tasks_cpu`) per task."""
    f = task_frame[r]
    nv = kind.shape[0]
    e, its = anneal_chain(
        start, free_idx, step, hist, nbins, th, dof_kind, lo, hi, max_redraws, n_end, n_l,
        n_tau, tau0, l0, c_l, c_tau, eps, stream_state(seed, frame_ids[f], task_run[r]),
        root_pos[f], root_rot[f], parent, chain, pre_rot, pre_trans, post_trans, elem_axis,
        elem_index, joint_flags, marker_joint, marker_local, slide_index, kind, P, K, dist, R,
        t, objective, points, conf, det_off[f * nv: f * nv + nv + 1], obs3[f], bidirectional,
        weight, cap, penalty_cap, False, 0, parent.shape[0], 0, marker_joint.shape[0],
        claimed, cur, cand, best, cs, sn, rot, pos, mk, proj, per_view, nearest,
        per_view[:0])  # no cloud on the GPU: no scratch for cloud_error_once
    for k in range(start.shape[0]):
        best_out[r, k] = best[k]
    e_out[r] = e
    it_out[r] = its


@njit(cache=True, nogil=True, parallel=True)
def anneal_tasks_cpu(na, nj, nm, nv, *args):
    """:func:`run_task` for every task (``args``: its parameters after ``r`` and before the
    scratch) on the CPU's threads, with scratch for ``na`` state entries, ``nj`` joints,
    ``nm`` markers and ``nv`` views: the GPU kernel's twin (the rounds' test oracle)."""
    for r in prange(args[0].shape[0]):
        run_task(r, *args, np.empty(na), np.empty(na), np.empty(na), np.empty(na),
                 np.empty(na), np.empty((nj, 3, 3)), np.empty((nj, 3)), np.empty((nm, 3)),
                 np.empty((nv, nm, 2)), np.empty(nv), np.empty(nm, np.int64))


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

        # numba's CUDA kernels take no *args: the kernel is written out with run_task's
        # parameters (all but r and the scratch, which are the thread's local arrays)
        names = ", ".join(list(inspect.signature(run_task.py_func).parameters)[1:-11])
        scratch = ", ".join(f"cuda.local.array({shape}, {dtype})[{cut}]" for shape, dtype, cut in (
            (na1, "float64", ":na"),) * 5 + (
            ((nj, 3, 3), "float64", ":"), ((nj, 3), "float64", ":"),
            ((nm1, 3), "float64", ":nm"), ((nv1, nm1, 2), "float64", ":nv, :nm"),
            (nv1, "float64", ":nv"), (nm1, "int64", ":nm")))
        source = (f"def anneal_tasks({names}):\n"
                  "    r = cuda.grid(1)\n"
                  "    if r < task_frame.shape[0]:\n"
                  f"        run_task(r, {names}, {scratch})\n")
        space = {"cuda": cuda, "run_task": run_task, "float64": float64, "int64": int64,
                 "na": na, "nm": nm, "nv": nv}
        exec(compile(source, f"<cuda kernel {key}>", "exec"), space)
        anneal_tasks = cuda.jit(fastmath=False)(space["anneal_tasks"])
        _kernels[key] = anneal_tasks
        return anneal_tasks


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
    objective, det_points, det_conf, det_off, obs3 = obs
    nv = cams[0].shape[0]
    nj = body[0].shape[0]
    nm = body[8].shape[0]
    na = best.shape[1]
    # the arrays taken out of the namedtuple first: stores through ``out.run_angles`` in a
    # prange were lost
    run_angles, run_error = out.run_angles, out.run_error
    for r in prange(task_frame.shape[0]):
        f = task_frame[r]
        run = task_run[r]
        state = best[r].copy()
        e_run, pairs, u = finish_run(
            state, e[r], root_pos[f], root_rot[f], body, cams, dofs, schedule, error,
            objective, det_points, det_conf, det_off[f * nv: f * nv + nv + 1], obs3[f],
            claim_gate, np.empty(na), np.empty(na), np.empty(na), np.empty((nj, 3, 3)),
            np.empty((nj, 3)), np.empty((nm, 3)), np.empty((nv, nm, 2)), np.empty(nv),
            np.empty(nm, np.int64))
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
    objective, det_points, det_conf, det_off, obs3 = obs
    min_runs, max_runs, threshold = schedule[17], schedule[12], schedule[11]
    max_unexplained = schedule[16]
    nv = cams[0].shape[0]
    nj = body[0].shape[0]
    nm = body[8].shape[0]
    na = out.angles.shape[1]
    cs, sn, keep = np.empty(na), np.empty(na), np.empty(na)
    rot, pos = np.empty((nj, 3, 3)), np.empty((nj, 3))
    mk, proj = np.empty((nm, 3)), np.empty((nv, nm, 2))
    per_view, near = np.empty(nv), np.empty(nm, np.int64)
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
                        objective, det_points, det_conf, det_off[f * nv: f * nv + nv + 1],
                        obs3[f], cs, sn, rot, pos, mk, proj, per_view, near)
    return frames[:k], runs[:k]


def fit_frames_rounds(frame_ids, root_pos, root_rot, start, body, cams, dofs, schedule,
                      error, obs, claim_gate, out, gpu=True):
    """The scalar ``fit_frames`` for independent frames (one partition, every run from
    ``start``; the same arguments and outputs), each round's runs annealed at once: on the
    GPU, or with ``gpu`` false by the kernel's CPU twin."""
    objective, points, conf, det_off, obs3 = obs
    nv = cams[0].shape[0]
    na, nj, nm = start.shape[0], body[0].shape[0], body[8].shape[0]
    first = min(max(schedule.min_runs, 1), schedule.max_runs)
    frames, runs = first_tasks(objective, det_off, obs3, nv, first, out)
    if not frames.size:
        return
    n = out.runs.shape[0]
    run_u = np.zeros((n, schedule.max_runs), np.int64)
    run_pairs = np.zeros((n, schedule.max_runs), np.int64)
    bidirectional, weight, cap, penalty_cap, _ = error
    inputs = (frame_ids, np.ascontiguousarray(root_pos), np.ascontiguousarray(root_rot), start,
              *dofs, schedule.max_redraws, schedule.n_end, schedule.n_l,
              schedule.n_tau, schedule.th, schedule.tau0, schedule.l0, schedule.c_l,
              schedule.c_tau, schedule.eps, schedule.seed, *body, *cams, objective, points,
              conf, det_off, obs3, bidirectional, weight, cap, penalty_cap,
              np.zeros(max(points.shape[0], obs3.shape[1], 1), np.bool_))
    if gpu:
        inputs = _on_gpu(inputs)
    while frames.size:
        t = frames.size
        best, e, its = np.empty((t, na)), np.empty(t), np.empty(t, np.int64)
        if gpu:
            _launch(_kernel(na, nj, nm, nv), frames, runs, inputs, best, e, its)
        else:
            anneal_tasks_cpu(na, nj, nm, nv, frames, runs, *inputs, best, e, its)
        finish_tasks(frames, runs, best, e, root_pos, root_rot, body, cams, dofs, schedule,
                     error, obs, claim_gate, out, run_u, run_pairs)
        frames, runs = next_tasks(frames, runs, its, root_pos, root_rot, body, cams,
                                  schedule, error, obs, out, run_u, run_pairs)


def _reason(what: str, exc: Exception) -> GpuFailed:
    """A :class:`GpuFailed` of one line: numba's CUDA errors span many lines (a typing
    error lists every candidate), so only the first line of the message is kept."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return GpuFailed(f"{what} ({type(exc).__name__}: {lines[0] if lines else 'no message'})")


def _on_gpu(inputs: tuple) -> tuple:
    """The kernel's inputs with every array copied to the GPU."""
    from numba import cuda
    try:
        return tuple(cuda.to_device(a) if isinstance(a, np.ndarray) else a for a in inputs)
    except Exception as exc:  # numba raises many kinds; the reason is in the message
        raise _reason("copying to the GPU failed", exc) from exc


def _launch(kernel, frames, runs, inputs, best, e, its) -> None:
    """One launch of ``kernel`` over the tasks (``frames``, ``runs``); its outputs into
    ``best``, ``e``, ``its``."""
    from numba import cuda
    try:
        d_best, d_e, d_its = (cuda.device_array_like(best), cuda.device_array_like(e),
                              cuda.device_array_like(its))
        kernel[-(-frames.size // THREADS), THREADS](
            cuda.to_device(frames), cuda.to_device(runs), *inputs, d_best, d_e, d_its)
        d_best.copy_to_host(best)
        d_e.copy_to_host(e)
        d_its.copy_to_host(its)
    except Exception as exc:  # compiling (the first launch) or running
        raise _reason("the GPU kernel failed", exc) from exc
