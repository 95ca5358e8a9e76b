"""numba kernels of the posture fitter: Eq. 5, the annealing loop of Eq. 6, re-analysis and
root-marker tracking (private; the public wrapper is :mod:`kinematics.fit`).

The readable twins are :mod:`kinematics.fit.error_function` (Eq. 5 and its variants) and
:func:`kinematics.fit.anneal_reference` (the annealing loop on the same random stream);
they are the specification and the test oracles.

Layout and conventions
----------------------
* Angles are radians. A posture is a flat vector of ``n_axes`` angles (y, x, z per joint).
* The body is passed in the *folded* layout of :func:`kinematics.fit.problem.fold_body`: the
  constant parts of Eq. 1 (R^s, R^d, T and the rotations of locked axes before the first
  and after the last free axis of a joint) are multiplied out once, so a joint costs one
  3×3 product plus one 12-flop column rotation per moving axis, and locked hinge axes cost
  nothing. Joint ``j`` keeps ``A'_j = A'_parent · G_j · Π rotations`` and
  ``p_j = p_parent + A'_parent · g_j + A'_j · h_j``; markers sit at ``p_j + A'_j · m``.
  Exact joint positions and marker positions; only the rotation matrices are reduced.
* Arrays are passed one by one, never as a tuple (unpacking a tuple of arrays in a
  non-inlined call costs atomic reference counts on every call).
* Detections of one frame are ragged: ``points`` (n, 2) pixels, view ``v`` owning rows
  ``view_off[v]:view_off[v + 1]``, sorted by x within each view
  (:func:`kinematics.fit.inputs.as_ragged`), so a view with many detections is searched by a
  sweep along x (:func:`nearest_sorted`). For many frames ``det_off`` (n_frames * n_views +
  1,) is frame-major; frame ``f``'s view offsets are
  ``det_off[f * n_views: (f + 1) * n_views + 1]``.
* Everything one annealing chain touches per iteration lives in caller-supplied scratch
  arrays (``cur``, ``cand``, ``best``, ``cs``, ``sn``, ``rot``, ``pos``, ``proj``), so the
  loop allocates nothing, and a later kernel can interleave many chains in SIMD lanes by
  giving these arrays a lane axis.
* Random numbers come from a counter-based splitmix64 stream per (seed, frame, run), so a
  frame's result does not depend on which thread fits it or how many threads there are.
* Hot loops are ``while i < n and not done`` loops without ``break``: a ``break`` kept
  reference counting inside a numba SA loop and made it 6.5x slower.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from kinematics._kernels.camera import ORTHOGRAPHIC, project_point

#: Cost of a model marker whose projection is undefined (behind a pinhole camera) when no
#: cap is set, in pixels.
NAN_MARKER_COST = 1.0e6

#: Bits of ``joint_flags`` in the folded layout.
G_IDENTITY = 1  # G_j is the identity: skip the 3×3 product
H_ZERO = 2  # h_j is zero: skip the translation
ROOT_POSE = 4  # a free root: per-frame seed rotation and state translation (slide_index)

#: Kinds of state entries (``dof_kind``): an angle whose histogram decides plausibility, or
#: a value (translation, or a free root's rotation offset) that must stay in [lo, hi].
DOF_HISTOGRAM = 0
DOF_RANGE = 1

# -- random numbers: splitmix64 (Steele, Lea & Flood 2014) --------------------------------
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_FRAME_KEY = np.uint64(0xD1B54A32D192ED03)
_RUN_KEY = np.uint64(0x8CB92BA72F3D8DD7)
_S11 = np.uint64(11)
_S27 = np.uint64(27)
_S30 = np.uint64(30)
_S31 = np.uint64(31)
_TWO_M53 = 1.0 / 9007199254740992.0  # 2**-53


@njit(cache=True, nogil=True, inline="always")
def mix64(z):
    """splitmix64's finaliser: a bijective 64-bit hash (z is uint64)."""
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


@njit(cache=True, nogil=True)
def stream_state(seed, frame, run):
    """Start state (uint64) of the random stream of (seed, frame, run), all integers >= 0."""
    s = mix64(np.uint64(seed) + _GOLDEN)
    s = mix64(s ^ (np.uint64(frame) * _FRAME_KEY))
    return mix64(s ^ (np.uint64(run) * _RUN_KEY + _GOLDEN))


@njit(cache=True, nogil=True, inline="always")
def next_uniform(state):
    """Advance the stream; returns ``(state, u)`` with ``u`` uniform in [0, 1) (53 bits)."""
    state = state + _GOLDEN
    return state, np.float64(mix64(state) >> _S11) * _TWO_M53


@njit(cache=True, nogil=True)
def uniforms(state, out):
    """Fill ``out`` with the stream's next draws (for tests); returns the new state."""
    st = np.uint64(state)  # a Python int may arrive as int64, and int64 + uint64 is float
    for k in range(out.shape[0]):
        st, out[k] = next_uniform(st)
    return st


# -- sine and cosine ----------------------------------------------------------------------
# Cody-Waite reduction by π/2 and the fdlibm kernels on [-π/4, π/4]: within 2 ulp of libm
# for |x| < 1e5 and twice as fast as np.sin + np.cos, which cost a fifth of an iteration.
_TWO_OVER_PI = 6.36619772367581382433e-01
_RINT = 6755399441055744.0  # 1.5 * 2**52: y + _RINT - _RINT rounds y to an integer, ties to
# even, exactly as np.rint for |y| < 2**51 (and for ±inf, NaN)
_PIO2_HI = 1.57079632673412561417e00
_PIO2_LO = 6.07710050650619224932e-11
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11


@njit(cache=True, nogil=True, inline="always")
def sincos(x):
    """``(sin x, cos x)`` for radians x. The quadrant is picked by selects, not branches, so
    a loop over SIMD lanes vectorises (:mod:`kinematics._kernels.lanes` uses it too)."""
    k = (x * _TWO_OVER_PI + _RINT) - _RINT  # np.rint, which numba's CUDA target lacks
    r = (x - k * _PIO2_HI) - k * _PIO2_LO
    z = r * r
    s = r + r * z * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    c = 1.0 - 0.5 * z + z * z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    q = int(k) & 3  # quadrants 0..3: (s, c), (c, -s), (-s, -c), (-c, s)
    s1 = c if q & 1 else s
    c1 = s if q & 1 else c
    s1 = -s1 if q >= 2 else s1
    c1 = -c1 if q == 1 or q == 2 else c1
    return s1, c1


# The same in float32 for the lanes' float32 kernels (kinematics._kernels.lane_codegen): π/2 in
# Cephes' three float32 parts and its single-precision polynomials; within 2 float32 ulp of
# the sine and cosine of x rounded to float32, for |x| < 1000 (tests/kinematics/
# test_lanes.py; rounding x itself costs up to 3e-5 at 1000, 5e-7 at 10).
_TWO_OVER_PI_F = np.float32(_TWO_OVER_PI)
_PIO2_F1, _PIO2_F2 = np.float32(1.5703125), np.float32(4.837512969970703125e-4)
_PIO2_F3 = np.float32(7.54978995489188216e-8)
_SF1, _SF2, _SF3 = np.float32(-1.6666654611e-1), np.float32(8.3321608736e-3), \
    np.float32(-1.9515295891e-4)
_CF1, _CF2, _CF3 = np.float32(4.166664568298827e-2), np.float32(-1.388731625493765e-3), \
    np.float32(2.443315711809948e-5)
_HALF_F, _ONE_F = np.float32(0.5), np.float32(1.0)


@njit(cache=True, nogil=True, inline="always")
def sincos32(x):
    """``(sin x, cos x)`` in float32 of a float64 x, quadrant picked by selects as
    :func:`sincos`."""
    xf = np.float32(x)
    k = np.rint(xf * _TWO_OVER_PI_F)
    r = ((xf - k * _PIO2_F1) - k * _PIO2_F2) - k * _PIO2_F3
    z = r * r
    s = r + r * z * (_SF1 + z * (_SF2 + z * _SF3))
    c = _ONE_F - _HALF_F * z + z * z * (_CF1 + z * (_CF2 + z * _CF3))
    q = np.int32(k) & 3
    s1 = c if q & 1 else s
    c1 = s if q & 1 else c
    s1 = -s1 if q >= 2 else s1
    c1 = -c1 if q == 1 or q == 2 else c1
    return s1, c1


# -- logarithm of a uniform draw ---------------------------------------------------------
# fdlibm's log (e_log.c): x = 2^k·m with m in [√2/2, √2), log(1 + f) by its degree-14
# polynomial in s = f / (2 + f); within 1 ulp. Written without branches (the exponent and
# mantissa taken from the bits) so a loop over SIMD lanes vectorises: libm's log is a call
# per lane that LLVM cannot vectorise, and it was 6 % of a lane iteration.
_LN2_HI, _LN2_LO = 6.93147180369123816490e-01, 1.90821492927058770002e-10
_LG1, _LG2, _LG3 = 6.666666666666735130e-01, 3.999999999940941908e-01, 2.857142874366239149e-01
_LG4, _LG5, _LG6 = 2.222219843214978396e-01, 1.818357216161805012e-01, 1.531383769920937332e-01
_LG7 = 1.479819860511658591e-01
_SQRT2 = 1.4142135623730951
_MANTISSA = np.uint64(0x000FFFFFFFFFFFFF)
_ONE_BITS = np.uint64(0x3FF0000000000000)
_S52 = np.uint64(52)


@njit(cache=True, nogil=True, inline="always")
def log_unit(x):
    """log(x) for a draw x in [0, 1) of :func:`next_uniform` (-inf for 0): fdlibm's log
    for positive normal numbers, which every non-zero draw is."""
    b = np.float64(x).view(np.uint64)
    k = np.float64(np.int64(b >> _S52) - 1023)
    m = np.uint64((b & _MANTISSA) | _ONE_BITS).view(np.float64)  # in [1, 2)
    big = m > _SQRT2
    m = 0.5 * m if big else m
    k = k + 1.0 if big else k
    f = m - 1.0
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (_LG2 + w * (_LG4 + w * _LG6))
    t2 = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7)))
    r = t2 + t1
    hfsq = 0.5 * f * f
    out = k * _LN2_HI - ((hfsq - (s * (hfsq + r) + k * _LN2_LO)) - f)
    return out if x > 0.0 else -np.inf


# -- histogram lookup ---------------------------------------------------------------------
@njit(cache=True, nogil=True, inline="always")
def hist_at(hist, nbins, i, x):
    """H_i(x) for x in radians: the value of the bin holding x (wraps), as
    :meth:`kinematics.model.histograms.Histogram.at`; no floating modulo in the common case."""
    n = nbins[i]
    nf = float(n)
    # floor((x_deg + 180) / (360 / n)) with multiplications only (a division per lookup
    # was a measurable part of the loop).
    k = int(math.floor(x * (nf * (0.5 / np.pi)) + 0.5 * nf))  # noqa: RUF046 (a float on CUDA)
    if k < 0 or k >= n:
        k = k % n
    return hist[i, k]


# -- forward kinematics and projection (Eq. 1-3), folded layout --------------------------
@njit(cache=True, nogil=True, inline="always")
def mul33(q00, q01, q02, q10, q11, q12, q20, q21, q22, m00, m01, m02, m10, m11, m12, m20, m21,
          m22):
    """The 3×3 product Q·M of two matrices given entry by entry (row-major), as nine
    numbers: kept to scalars so a loop over SIMD lanes that calls it still vectorises
    (:mod:`kinematics._kernels.lanes`)."""
    return (q00 * m00 + q01 * m10 + q02 * m20, q00 * m01 + q01 * m11 + q02 * m21,
            q00 * m02 + q01 * m12 + q02 * m22, q10 * m00 + q11 * m10 + q12 * m20,
            q10 * m01 + q11 * m11 + q12 * m21, q10 * m02 + q11 * m12 + q12 * m22,
            q20 * m00 + q21 * m10 + q22 * m20, q20 * m01 + q21 * m11 + q22 * m21,
            q20 * m02 + q21 * m12 + q22 * m22)


@njit(cache=True, nogil=True, inline="always")
def _project_cs(values, cs, sn, root_pos, root_rot, parent, chain, pre_rot, pre_trans,
                post_trans, elem_axis, elem_index, joint_flags, marker_joint, marker_local,
                slide_index, kind, P, K, dist, R, t, rot, pos, mk, proj, any_pinhole, span,
                marks):
    """Markers of the posture with cosines ``cs`` and sines ``sn`` (n_axes,) projected into
    every view: fills ``proj`` (n_views, n_markers, 2); ``rot`` (nj, 3, 3), ``pos`` (nj, 3)
    and ``mk`` (nm, 3) receive A'_j, the joint centres and the 3D markers.
    ``any_pinhole`` says whether ``kind`` has a pinhole view. A marker hidden in a pinhole
    view by ``marks`` (a frame's hidden marks, :func:`hidden_in`; an empty array for none)
    is not projected there: every reader skips it, and with one view per camera and marker
    colour most markers are hidden in most views. ``span = (j0, j1, m0, m1)``:
    only joints ``j0:j1`` and markers ``m0:m1`` are computed (a partition's subtree; its
    parents' ``rot``, ``pos`` must be current); ``(0, nj, 0, nm)`` computes everything. (One
    tuple, not four numbers: a call with more than 30 arguments compiles to a star-args call,
    which numba cannot inline.)"""
    j0, j1, m0, m1 = span
    for j in range(j0, j1):
        p = parent[j]
        if p < 0:
            c = chain[j]
            b00, b01, b02 = pre_rot[j, 0, 0], pre_rot[j, 0, 1], pre_rot[j, 0, 2]
            b10, b11, b12 = pre_rot[j, 1, 0], pre_rot[j, 1, 1], pre_rot[j, 1, 2]
            b20, b21, b22 = pre_rot[j, 2, 0], pre_rot[j, 2, 1], pre_rot[j, 2, 2]
            px, py, pz = root_pos[c, 0], root_pos[c, 1], root_pos[c, 2]
            if joint_flags[j] & ROOT_POSE:
                # A free root: the frame's seed rotation root_rot[c] comes first and the
                # state's translation entries (slide_index) move the root in the world.
                q = root_rot[c]
                b00, b01, b02, b10, b11, b12, b20, b21, b22 = mul33(
                    q[0, 0], q[0, 1], q[0, 2], q[1, 0], q[1, 1], q[1, 2], q[2, 0], q[2, 1],
                    q[2, 2], b00, b01, b02, b10, b11, b12, b20, b21, b22)
                k = slide_index[j]
                px += values[k]
                py += values[k + 1]
                pz += values[k + 2]
        else:
            q00, q01, q02 = rot[p, 0, 0], rot[p, 0, 1], rot[p, 0, 2]
            q10, q11, q12 = rot[p, 1, 0], rot[p, 1, 1], rot[p, 1, 2]
            q20, q21, q22 = rot[p, 2, 0], rot[p, 2, 1], rot[p, 2, 2]
            g0, g1, g2 = pre_trans[j, 0], pre_trans[j, 1], pre_trans[j, 2]
            px = pos[p, 0] + q00 * g0 + q01 * g1 + q02 * g2
            py = pos[p, 1] + q10 * g0 + q11 * g1 + q12 * g2
            pz = pos[p, 2] + q20 * g0 + q21 * g1 + q22 * g2
            if joint_flags[j] & G_IDENTITY:
                b00, b01, b02 = q00, q01, q02
                b10, b11, b12 = q10, q11, q12
                b20, b21, b22 = q20, q21, q22
            else:
                m00, m01, m02 = pre_rot[j, 0, 0], pre_rot[j, 0, 1], pre_rot[j, 0, 2]
                m10, m11, m12 = pre_rot[j, 1, 0], pre_rot[j, 1, 1], pre_rot[j, 1, 2]
                m20, m21, m22 = pre_rot[j, 2, 0], pre_rot[j, 2, 1], pre_rot[j, 2, 2]
                b00, b01, b02, b10, b11, b12, b20, b21, b22 = mul33(
                    q00, q01, q02, q10, q11, q12, q20, q21, q22, m00, m01, m02, m10, m11, m12,
                    m20, m21, m22)
        for e in range(3):
            a = elem_axis[j, e]
            if a >= 0:
                # Right-multiplying by an elementary rotation about world axis a mixes the
                # two other columns (x: columns 1, 2; y: 2, 0; z: 0, 1).
                c = cs[elem_index[j, e]]
                s = sn[elem_index[j, e]]
                if a == 0:
                    b01, b02 = c * b01 + s * b02, c * b02 - s * b01
                    b11, b12 = c * b11 + s * b12, c * b12 - s * b11
                    b21, b22 = c * b21 + s * b22, c * b22 - s * b21
                elif a == 1:
                    b02, b00 = c * b02 + s * b00, c * b00 - s * b02
                    b12, b10 = c * b12 + s * b10, c * b10 - s * b12
                    b22, b20 = c * b22 + s * b20, c * b20 - s * b22
                else:
                    b00, b01 = c * b00 + s * b01, c * b01 - s * b00
                    b10, b11 = c * b10 + s * b11, c * b11 - s * b10
                    b20, b21 = c * b20 + s * b21, c * b21 - s * b20
        if not joint_flags[j] & H_ZERO:
            h0, h1, h2 = post_trans[j, 0], post_trans[j, 1], post_trans[j, 2]
            px += b00 * h0 + b01 * h1 + b02 * h2
            py += b10 * h0 + b11 * h1 + b12 * h2
            pz += b20 * h0 + b21 * h1 + b22 * h2
        rot[j, 0, 0], rot[j, 0, 1], rot[j, 0, 2] = b00, b01, b02
        rot[j, 1, 0], rot[j, 1, 1], rot[j, 1, 2] = b10, b11, b12
        rot[j, 2, 0], rot[j, 2, 1], rot[j, 2, 2] = b20, b21, b22
        pos[j, 0], pos[j, 1], pos[j, 2] = px, py, pz
    for m in range(m0, m1):
        j = marker_joint[m]
        a0, a1, a2 = marker_local[m, 0], marker_local[m, 1], marker_local[m, 2]
        x = pos[j, 0] + rot[j, 0, 0] * a0 + rot[j, 0, 1] * a1 + rot[j, 0, 2] * a2
        y = pos[j, 1] + rot[j, 1, 0] * a0 + rot[j, 1, 1] * a1 + rot[j, 1, 2] * a2
        z = pos[j, 2] + rot[j, 2, 0] * a0 + rot[j, 2, 1] * a1 + rot[j, 2, 2] * a2
        mk[m, 0] = x
        mk[m, 1] = y
        mk[m, 2] = z
        # Every view as orthographic (project_point's first case, inlined); pinhole views
        # are overwritten below. A call to project_point inside this loop, even untaken,
        # cost ~10 % of an iteration.
        for v in range(kind.shape[0]):
            proj[v, m, 0] = P[v, 0, 0] * x + P[v, 0, 1] * y + P[v, 0, 2] * z + P[v, 0, 3]
            proj[v, m, 1] = P[v, 1, 0] * x + P[v, 1, 1] * y + P[v, 1, 2] * z + P[v, 1, 3]
    if any_pinhole:
        _project_pinhole(kind, P, K, dist, R, t, mk, proj, m0, m1, marks)


@njit(cache=True, nogil=True)
def _project_pinhole(kind, P, K, dist, R, t, mk, proj, m0, m1, marks):
    """Project the 3D markers ``mk[m0:m1]`` into the pinhole views of ``proj``, but not
    where ``marks`` hides them (:func:`hidden_in`)."""
    skip = marks.shape[0] > 0  # tested once: a test per marker slowed every pinhole fit
    for v in range(kind.shape[0]):
        if kind[v] != ORTHOGRAPHIC:
            for m in range(m0, m1):
                if skip and hidden_in(marks, m, v):
                    continue
                u, w = project_point(kind, P, K, dist, R, t, v, mk[m, 0], mk[m, 1], mk[m, 2])
                proj[v, m, 0] = u
                proj[v, m, 1] = w


@njit(cache=True, nogil=True, inline="always")
def _has_pinhole(kind):
    out = False
    for v in range(kind.shape[0]):
        out = out or kind[v] != ORTHOGRAPHIC
    return out


@njit(cache=True, nogil=True, inline="always")
def _drawn_views(kind, objective):
    """The views a search projects its draws into (``kind``, sliced): none where the
    objective is 3D (points or a cloud), which reads only the 3D markers."""
    return kind[:0] if objective in (OBJ_POINTS3D, OBJ_CLOUD) else kind[:]


@njit(cache=True, nogil=True)
def project_posture(angles, root_pos, root_rot, parent, chain, pre_rot, pre_trans, post_trans,
                    elem_axis, elem_index, joint_flags, marker_joint, marker_local, slide_index,
                    kind, P, K, dist, R, t, cs, sn, rot, pos, mk, proj):
    """Forward kinematics (Eq. 1, 2) and projection (Eq. 3) of every marker of posture
    ``angles`` (n_axes,) radians into every view: fills ``proj`` (n_views, n_markers, 2);
    ``cs``, ``sn`` (n_axes,), ``rot`` (nj, 3, 3), ``pos`` (nj, 3), ``mk`` (nm, 3) are
    scratch (holding the joint centres and 3D markers afterwards)."""
    for k in range(angles.shape[0]):
        sn[k], cs[k] = sincos(angles[k])
    _project_cs(angles, cs, sn, root_pos, root_rot, parent, chain, pre_rot, pre_trans,
                post_trans, elem_axis, elem_index, joint_flags, marker_joint, marker_local,
                slide_index, kind, P, K, dist, R, t, rot, pos, mk, proj, _has_pinhole(kind),
                (0, parent.shape[0], 0, marker_joint.shape[0]), mk[:0])


# -- Eq. 5 -------------------------------------------------------------------------------
#: Views with more detections than this are searched by :func:`nearest_sorted`; with fewer
#: a plain scan is faster (and the paper's few markers per view keep their exact code path).
#: Measured on the fly (bench_scaling): a leg's iteration 3.5 → 2.7 µs at 100 detections per
#: view, slower at 30. The fast path's four-chain scan (:func:`_paper_error`) costs a third
#: as much per detection, so it sweeps only from SWEEP_MIN_FAST: whole-body iterations of the
#: fly were 16 → 20 µs at 100 detections with the sweep, 35 → 28 µs at 300.
SWEEP_MIN = 64
SWEEP_MIN_FAST = 192
NO_CLAIMS = np.zeros(0, np.bool_)  # the whole body: no partition claims a point
#: ``nearest`` entry of a model marker hidden in the view (:func:`hidden_in`): it takes no
#: point (:func:`takes` is false for every point) and costs nothing.
UNSEEN = -(1 << 62)
NO_HIDDEN = np.zeros((0, 4))  # a frame's obs3 without hidden marks (:func:`hidden_in`)


@njit(cache=True, nogil=True, inline="always")
def hidden_in(obs3, i, v):
    """Whether unlabelled 2D points skip model marker ``i`` in view ``v`` because the user
    marked it hidden there (occluded, or its blob merged with another). For unlabelled
    points a frame's ``obs3`` holds these marks, shape (n_markers, n_views), nonzero =
    hidden; an array of any other shape (e.g. (0, 4)) hides nothing. A hidden marker costs
    nothing in that view, takes no detection and explains none."""
    return i < obs3.shape[0] and v < obs3.shape[1] and obs3[i, v] != 0.0


@njit(cache=True, nogil=True, inline="always")
def nearest_sorted(px, py, points, a, b, claimed):
    """The nearest detection to (px, py) among rows ``a:b``, which are sorted by x, not
    ``claimed`` (an empty ``claimed`` claims nothing): a binary search for px, then outward
    while the x gap alone is no farther than the best so far, so a query costs the detections
    in a band around the marker, not all. Returns (squared distance, row), (inf, -1) for
    none; ties go to the lower row, as a scan's."""
    lo = a
    hi = b
    while lo < hi:
        mid = (lo + hi) // 2
        if points[mid, 0] < px:
            lo = mid + 1
        else:
            hi = mid
    best = np.inf
    arg = -1
    nc = claimed.shape[0]
    # Rightward from the insertion point, then leftward, in two written-out loops: a merged
    # loop with a step was 1.3x slower per query at 1000 detections, and the shared body as
    # an inline helper returning (best, row) 3x slower (156-169 -> 495-507 ns per query).
    c = lo
    gap = 0.0
    while c < b and gap <= best:
        dx = points[c, 0] - px
        gap = dx * dx
        dy = points[c, 1] - py
        d2 = gap + dy * dy
        if (d2 < best or (d2 == best and c < arg)) and not (c < nc and claimed[c]):
            best = d2
            arg = c
        c += 1
    c = lo - 1
    gap = 0.0
    while c >= a and gap <= best:
        dx = px - points[c, 0]
        gap = dx * dx
        dy = points[c, 1] - py
        d2 = gap + dy * dy
        if (d2 < best or (d2 == best and c < arg)) and not (c < nc and claimed[c]):
            best = d2
            arg = c
        c -= 1
    return best, arg


@njit(cache=True, nogil=True, inline="always")
def nearest_in_view(px, py, points, a, b, claimed):
    """The nearest detection to (px, py) among rows ``a:b`` not ``claimed`` (an empty
    ``claimed`` claims nothing): by :func:`nearest_sorted` in a view with many detections,
    else by a scan. Returns (squared distance, row), (inf, -1) for none."""
    if b - a > SWEEP_MIN:
        return nearest_sorted(px, py, points, a, b, claimed)
    best = np.inf
    arg = -1
    nc = claimed.shape[0]
    for c in range(a, b):
        dx = px - points[c, 0]
        dy = py - points[c, 1]
        d2 = dx * dx + dy * dy
        if d2 < best and not (c < nc and claimed[c]):
            best = d2
            arg = c
    return best, arg


@njit(cache=True, nogil=True)
def projection_error(proj, points, view_off, obs3, bidirectional, weight, cap, penalty_cap,
                     one, per_view, nearest):
    """Eq. 5 and its variants for given marker projections; returns E (pixels).

    ``E = sum_v sum_i min(min_c |p_i^v - d_c^v|, cap)`` over views with at least one
    detection (a view without detections contributes nothing). With ``bidirectional``, each
    detection that is no marker's nearest detection adds ``weight * min(min_i |p_i^v -
    d_c^v|, penalty_cap)`` (the heuristic of Sect. 4; bounded, a ghost costs at most
    ``weight * penalty_cap``). ``cap = inf`` is the paper's Eq. 5. With ``one`` (one-to-one)
    each detection explains at most one marker of its view (:func:`one_to_one`). Ties go
    to the lower detection index. A marker without a finite projection costs ``cap``, or
    :data:`NAN_MARKER_COST` without a cap. A marker hidden in a view (:func:`hidden_in`)
    is left out of that view.

    Parameters
    ----------
    proj : (n_views, n_markers, 2)
    points : (n_points, 2); view_off : (n_views + 1,); obs3 : hidden marks (:func:`hidden_in`)
    per_view : (n_views,) out, E of each view; nearest : (n_markers,) int64 scratch.
    """
    nv = proj.shape[0]
    nm = proj.shape[1]
    missing = cap if cap < np.inf else NAN_MARKER_COST
    total = 0.0
    for v in range(nv):
        a = view_off[v]
        b = view_off[v + 1]
        ev = 0.0
        if b > a:
            for i in range(nm):
                if hidden_in(obs3, i, v):
                    nearest[i] = UNSEEN
                    continue
                best, arg = nearest_in_view(proj[v, i, 0], proj[v, i, 1], points, a, b,
                                            NO_CLAIMS)
                nearest[i] = arg
                d = math.sqrt(best) if arg >= 0 else missing
                ev += min(d, cap)
            if one:
                ev = one_to_one(proj[v], points, a, b, 0, nm, False, NO_CLAIMS, cap, nearest)
            if bidirectional:
                for c in range(a, b):
                    matched = False
                    best = np.inf
                    for i in range(nm):
                        matched = matched or takes(nearest[i], c)
                        dx = proj[v, i, 0] - points[c, 0]
                        dy = proj[v, i, 1] - points[c, 1]
                        seen = nearest[i] != UNSEEN
                        best = min(best, dx * dx + dy * dy) if seen else best
                    if not matched:
                        d = math.sqrt(best) if best < np.inf else missing
                        ev += weight * min(d, penalty_cap)
        per_view[v] = ev
        total += ev
    return total


@njit(cache=True, nogil=True, inline="always")
def takes(n, c):
    """Whether a marker's ``nearest`` entry ``n`` takes point ``c``: its nearest point, or
    the point :func:`one_to_one` gave it instead, written ``-(c + 2)``."""
    return n == c or n == -c - 2


@njit(cache=True, nogil=True, inline="always")
def point_of(n):
    """The point a marker's ``nearest`` entry ``n`` takes: ``n``, or for a marker that lost
    its nearest point the one :func:`one_to_one` gave it instead (``-(c + 2)``); -1 none."""
    return n if n >= -1 else -n - 2


@njit(cache=True, nogil=True, inline="always")
def may_take(cloud, c, i):
    """Whether model marker ``i`` may take cloud point ``c``. A cloud of markers of several
    colours (each colour triangulated on its own) has one column per model marker after x,
    y, z, s: nonzero where the marker has the point's colour; a cloud of 4 columns lets
    every marker take every point."""
    return cloud.shape[1] <= 4 or cloud[c, 4 + i] != 0.0


@njit(cache=True, nogil=True, inline="always")
def _dist2(X, i, Y, c, scaled):
    """Squared distance of marker ``X[i]`` to point ``Y[c]``: 2D, or with ``scaled`` 3D times
    the point's px per length unit ``Y[c, 3]`` squared (a cloud; infinite where the marker
    may not take the point, :func:`may_take`)."""
    dx = X[i, 0] - Y[c, 0]
    dy = X[i, 1] - Y[c, 1]
    d2 = dx * dx + dy * dy
    if scaled:
        dz = X[i, 2] - Y[c, 2]
        d2 = (d2 + dz * dz) * (Y[c, 3] * Y[c, 3]) if may_take(Y, c, i) else np.inf
    return d2


@njit(cache=True, nogil=True)
def one_to_one(X, Y, a, b, m0, m1, scaled, claimed, cap, nearest):
    """One-to-one matching of the markers ``m0:m1`` (``X``) with the points ``a:b`` (``Y``;
    with ``scaled`` a cloud, :func:`_dist2`), greedy by distance: a point several markers
    have as their nearest stays with the closest (ties: the lower marker); each other marker
    takes its nearest point that is no marker's nearest and not ``claimed``, or costs
    ``cap`` (:data:`NAN_MARKER_COST` without one) where none is left. On entry ``nearest``
    holds each marker's nearest point (-1: none; :data:`UNSEEN`: hidden, left out); on
    return a marker that lost its point holds ``-(c + 2)`` for the point ``c`` it took
    instead (:func:`takes`). Returns
    ``sum_i min(distance_i, cap)``. So two limbs cannot share a blob: the second marker
    pays for its next point, and the marker it leaves out pays the bidirectional term."""
    missing = cap if cap < np.inf else NAN_MARKER_COST
    for i in range(m0, m1):  # losers: nearest = -(their point + 2)
        c = nearest[i]
        if c >= 0:
            di = _dist2(X, i, Y, c, scaled)
            lost = False
            for j in range(m0, m1):
                cj = point_of(nearest[j])
                if j != i and cj == c:
                    dj = _dist2(X, j, Y, c, scaled)
                    lost = lost or dj < di or (dj == di and j < i)
            if lost:
                nearest[i] = -c - 2
    total = 0.0
    for i in range(m0, m1):
        c = nearest[i]
        if c >= 0:
            total += min(math.sqrt(_dist2(X, i, Y, c, scaled)), cap)
        elif c == -1:
            total += min(missing, cap)
        elif c != UNSEEN:  # lost its point: the nearest one no marker has as its nearest
            best = np.inf
            arg = -1
            for c2 in range(a, b):
                free = not (c2 < claimed.shape[0] and claimed[c2])
                free = free and (not scaled or Y[c2, 3] > 0.0)
                for j in range(m0, m1):
                    free = free and nearest[j] != c2
                if free:
                    d2 = _dist2(X, i, Y, c2, scaled)
                    if d2 < best:
                        best = d2
                        arg = c2
            nearest[i] = -arg - 2 if arg >= 0 else -1
            total += min(math.sqrt(best) if arg >= 0 else missing, cap)
    return total


@njit(cache=True, nogil=True, inline="always")
def _paper_error(proj, points, view_off, cap):
    """:func:`projection_error` without the bidirectional term and per-view output: the
    annealing loop's fast path. The minimum over detections runs in four independent
    chains (a single chain of dependent minimums was latency-bound); min is exact, so the
    result equals :func:`projection_error`'s."""
    missing = cap if cap < np.inf else NAN_MARKER_COST
    total = 0.0
    for v in range(proj.shape[0]):
        a = view_off[v]
        b = view_off[v + 1]
        ev = 0.0
        if b - a > SWEEP_MIN_FAST:
            for i in range(proj.shape[1]):
                best, _ = nearest_sorted(proj[v, i, 0], proj[v, i, 1], points, a, b,
                                         NO_CLAIMS)
                d = math.sqrt(best) if best < np.inf else missing
                ev += min(d, cap)
        elif b > a:
            for i in range(proj.shape[1]):
                px = proj[v, i, 0]
                py = proj[v, i, 1]
                m0 = np.inf
                m1 = np.inf
                m2 = np.inf
                m3 = np.inf
                c = a
                while c + 3 < b:
                    dx = px - points[c, 0]
                    dy = py - points[c, 1]
                    m0 = min(m0, dx * dx + dy * dy)
                    dx = px - points[c + 1, 0]
                    dy = py - points[c + 1, 1]
                    m1 = min(m1, dx * dx + dy * dy)
                    dx = px - points[c + 2, 0]
                    dy = py - points[c + 2, 1]
                    m2 = min(m2, dx * dx + dy * dy)
                    dx = px - points[c + 3, 0]
                    dy = py - points[c + 3, 1]
                    m3 = min(m3, dx * dx + dy * dy)
                    c += 4
                while c < b:
                    dx = px - points[c, 0]
                    dy = py - points[c, 1]
                    m0 = min(m0, dx * dx + dy * dy)
                    c += 1
                best = min(min(m0, m1), min(m2, m3))
                d = math.sqrt(best) if best < np.inf else missing
                ev += min(d, cap)
        total += ev
    return total


#: Objectives (``objective``): which error E a posture is scored by.
OBJ_NEAREST = 0  # unlabelled points per view: Eq. 5 and its variants
OBJ_LABELLED = 1  # labelled 2D keypoints: marker i of view v against its own keypoint
OBJ_POINTS3D = 2  # labelled 3D points: marker i against its own 3D point
OBJ_CLOUD = 3  # unlabelled 3D points (detections triangulated across views): nearest point
# refinement only (the final polish, Fitter._polished): the cloud paired one to one, and
# with _VIEWS a marker left without a point paired in each view with its nearest detection
OBJ_CLOUD_ONE = 4
OBJ_CLOUD_VIEWS = 5


@njit(cache=True, nogil=True)
def labelled_error(proj, points, conf, view_off, cap, per_view):
    """Labelled reprojection error: ``E = sum_v sum_i w_i^v min(|p_i^v - k_i^v|, cap)``.

    View ``v`` owns rows ``view_off[v]:view_off[v + 1]``, which are the model markers in
    order (``n_markers`` rows) or none; a keypoint that is not finite or has weight
    ``conf <= 0`` is missing and costs nothing; a marker whose projection is not finite costs
    ``cap`` (:data:`NAN_MARKER_COST` without a cap), times its weight.
    """
    missing = cap if cap < np.inf else NAN_MARKER_COST
    total = 0.0
    for v in range(proj.shape[0]):
        a = view_off[v]
        ev = 0.0
        if view_off[v + 1] - a == proj.shape[1]:
            for i in range(proj.shape[1]):
                w = conf[a + i]
                kx = points[a + i, 0]
                ky = points[a + i, 1]
                if w > 0.0 and math.isfinite(kx) and math.isfinite(ky):
                    dx = proj[v, i, 0] - kx
                    dy = proj[v, i, 1] - ky
                    d = math.sqrt(dx * dx + dy * dy)
                    ev += w * min(d if math.isfinite(d) else missing, cap)
        per_view[v] = ev
        total += ev
    return total


@njit(cache=True, nogil=True)
def points3d_error(mk, obs, cap):
    """3D point error: ``E = sum_i w_i min(|X_i - Y_i|, cap)`` over the markers whose point
    ``obs[i] = (x, y, z, w)`` is finite with ``w > 0``; in the body's length units."""
    total = 0.0
    for i in range(mk.shape[0]):
        w = obs[i, 3]
        if w > 0.0 and math.isfinite(obs[i, 0]) and math.isfinite(obs[i, 1]) and math.isfinite(
                obs[i, 2]):
            dx = mk[i, 0] - obs[i, 0]
            dy = mk[i, 1] - obs[i, 1]
            dz = mk[i, 2] - obs[i, 2]
            total += w * min(math.sqrt(dx * dx + dy * dy + dz * dz), cap)
    return total


@njit(cache=True, nogil=True, inline="always")
def cloud_nearest(mk, i, cloud, claimed):
    """Marker ``i``'s nearest cloud point not ``claimed`` (in px-equivalents: the 3D
    distance times the point's px per length unit, ``cloud[c, 3]``; 0 marks padding) among
    those it may take (:func:`may_take`); returns (distance, row), row -1 when there is
    none."""
    best = np.inf
    arg = -1
    for c in range(cloud.shape[0]):
        s = cloud[c, 3]
        dx = mk[i, 0] - cloud[c, 0]
        dy = mk[i, 1] - cloud[c, 1]
        dz = mk[i, 2] - cloud[c, 2]
        d2 = s * s * (dx * dx + dy * dy + dz * dz)
        if s > 0.0 and d2 < best and not (c < claimed.shape[0] and claimed[c]) and (
                may_take(cloud, c, i)):
            best = d2
            arg = c
    return math.sqrt(best), arg


@njit(cache=True, nogil=True)
def cloud_error(mk, cloud, m0, m1, claimed, penalty, cap, penalty_cap, one, nearest):
    """Unlabelled 3D points (:data:`OBJ_CLOUD`), the 3D twin of Eq. 5: ``E = sum_i
    min(s_c |X_i - Y_c|, cap)`` over the markers ``m0:m1``, ``Y_c`` marker i's nearest cloud
    point among those not ``claimed`` (by other partitions; an empty ``claimed`` claims
    nothing) and ``s_c`` its px per length unit (``cloud`` (k, 4): x, y, z, s; s = 0 marks
    padding; with a column per marker after them, only where it may take the point,
    :func:`may_take`), so E reads in pixels like Eq. 5's. With ``penalty > 0`` (the
    bidirectional modes) each unclaimed point that none of these markers takes adds
    ``penalty · min(s_c · distance to the nearest of them that may take it, penalty_cap)``
    (nothing where none may). With ``one`` each point explains at
    most one marker (:func:`one_to_one`). ``nearest`` (n_markers,) is scratch."""
    missing = cap if cap < np.inf else NAN_MARKER_COST
    total = 0.0
    for i in range(m0, m1):
        d, nearest[i] = cloud_nearest(mk, i, cloud, claimed)
        total += min(d if nearest[i] >= 0 else missing, cap)
    if one:
        total = one_to_one(mk, cloud, 0, cloud.shape[0], m0, m1, True, claimed, cap, nearest)
    if penalty > 0.0:
        for c in range(cloud.shape[0]):
            s = cloud[c, 3]
            taken = s <= 0.0 or (c < claimed.shape[0] and claimed[c])
            best = np.inf
            for i in range(m0, m1):
                taken = taken or takes(nearest[i], c)
                dx = mk[i, 0] - cloud[c, 0]
                dy = mk[i, 1] - cloud[c, 1]
                dz = mk[i, 2] - cloud[c, 2]
                if may_take(cloud, c, i):
                    best = min(best, dx * dx + dy * dy + dz * dz)
            if not taken and best < np.inf:
                total += penalty * min(s * math.sqrt(best), penalty_cap)
    return total


@njit(cache=True, nogil=True, inline="always")
def cloud_error_once(mk, cloud, m0, m1, penalty, cap, penalty_cap, nearest, marker_d2,
                     point_d2):
    """:func:`cloud_error` of a cloud nothing is claimed from, without one-to-one: the same
    E to the bit, each marker-point distance computed once for both terms (the nearest
    point of each marker and the nearest marker of each point; :func:`cloud_error` computes
    them twice). Points outer, markers inner, so each marker's search still meets the
    points in order (ties to the lower row). ``marker_d2`` (n_markers,), ``point_d2``
    (n_points or more,) float scratch."""
    missing = cap if cap < np.inf else NAN_MARKER_COST
    for i in range(m0, m1):
        marker_d2[i] = np.inf
        nearest[i] = -1
    for c in range(cloud.shape[0]):
        s = cloud[c, 3]
        nearest_c = np.inf
        if s > 0.0:
            ss = s * s
            for i in range(m0, m1):
                if may_take(cloud, c, i):
                    dx = mk[i, 0] - cloud[c, 0]
                    dy = mk[i, 1] - cloud[c, 1]
                    dz = mk[i, 2] - cloud[c, 2]
                    d2 = dx * dx + dy * dy + dz * dz
                    if ss * d2 < marker_d2[i]:
                        marker_d2[i] = ss * d2
                        nearest[i] = c
                    nearest_c = min(nearest_c, d2)
        point_d2[c] = nearest_c
    total = 0.0
    for i in range(m0, m1):
        total += min(math.sqrt(marker_d2[i]) if nearest[i] >= 0 else missing, cap)
    if penalty > 0.0:
        for c in range(cloud.shape[0]):
            taken = cloud[c, 3] <= 0.0
            for i in range(m0, m1):
                taken = taken or takes(nearest[i], c)
            if not taken and point_d2[c] < np.inf:
                total += penalty * min(cloud[c, 3] * math.sqrt(point_d2[c]), penalty_cap)
    return total


@njit(cache=True, nogil=True)
def claim_cloud(mk, cloud, claimers, gate, claimed):
    """:func:`claim_detections` for a 3D cloud: each marker flagged in ``claimers`` claims
    its nearest point within ``gate`` px-equivalents."""
    claimed[:] = False
    for i in range(mk.shape[0]):
        if not claimers[i]:
            continue
        d, arg = cloud_nearest(mk, i, cloud, claimed[:0])
        if arg >= 0 and d <= gate:
            claimed[arg] = True


@njit(cache=True, nogil=True)
def unclaimed_cloud(cloud, claimed):
    """The rows of ``cloud`` that are points (s > 0) and not ``claimed``, in order, and an
    empty claim mask: what :func:`cloud_error` scores with ``claimed``, to the bit, without
    testing every claimed or padding row on every call (a limb's search and annealing score
    the same points hundreds of thousands of times; in a later round every other limb's
    points are claimed)."""
    keep = np.empty(cloud.shape[0], np.int64)
    n = 0
    for c in range(cloud.shape[0]):
        if cloud[c, 3] > 0.0 and not (c < claimed.shape[0] and claimed[c]):
            keep[n] = c
            n += 1
    out = np.empty((n, cloud.shape[1]))
    for k in range(n):
        out[k, :] = cloud[keep[k]]
    return out, np.zeros(0, np.bool_)


@njit(cache=True, nogil=True)
def count_unexplained_cloud(mk, cloud, gate):
    """Cloud points farther than ``gate`` px-equivalents from every model marker."""
    n = 0
    for c in range(cloud.shape[0]):
        s = cloud[c, 3]
        near = s <= 0.0
        for i in range(mk.shape[0]):
            dx = mk[i, 0] - cloud[c, 0]
            dy = mk[i, 1] - cloud[c, 1]
            dz = mk[i, 2] - cloud[c, 2]
            near = near or (s * math.sqrt(dx * dx + dy * dy + dz * dz) <= gate and
                            may_take(cloud, c, i))
        n += 0 if near else 1
    return n


@njit(cache=True, nogil=True, inline="always")
def _nan_min(a, b):
    """``min`` as NumPy's ``min`` reduces: a NaN on either side wins."""
    return a if math.isnan(a) or not (b < a or math.isnan(b)) else b


@njit(cache=True, nogil=True)
def nearest_residuals(proj, points, view_off, seen, gate, out):
    """Each seen model marker's distance to the nearest detection of its view into ``out``
    (n_views, n_markers; left as it is for a view without detections or a marker not
    seen); returns the detections farther than ``gate`` (finite) from every seen marker of
    their view (all of a view that sees none). NaN propagates as in NumPy (a marker behind a
    camera). Twin: :func:`kinematics.fit.error_function.nearest_residuals`."""
    unexplained = 0
    nm = proj.shape[1]
    for v in range(proj.shape[0]):
        a, b = view_off[v], view_off[v + 1]
        near = np.full(b - a, np.inf)  # per detection, its nearest seen marker (none: inf)
        for m in range(nm):
            if seen[v, m] and b > a:
                best = np.inf
                for c in range(a, b):
                    dx = proj[v, m, 0] - points[c, 0]
                    dy = proj[v, m, 1] - points[c, 1]
                    d = math.sqrt(dx * dx + dy * dy)
                    best = _nan_min(best, d)
                    near[c - a] = _nan_min(near[c - a], d)
                out[v, m] = best
        for c in range(b - a):
            unexplained += 1 if near[c] > gate else 0
    return unexplained


@njit(cache=True, nogil=True)
def block_residuals(states, ran, root_pos, root_rot, body, cams, points, offsets, gate, out,
                    unexplained):
    """:func:`nearest_residuals` of many frames' fitted postures in one call (a block's
    results; per frame from Python it was a third of the per-frame Python): for each frame k
    with ``ran[k]``, posture ``states[k]`` projected and every marker's distance to the
    nearest detection of its view written into ``out[k]`` (n_views, n_markers), the
    detections farther than ``gate`` from every marker counted into ``unexplained[k]``.
    ``offsets`` (n_frames * n_views + 1) index ``points``; every marker is seen."""
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = body
    kind, P, K, dist, R, t = cams
    nv, nm, na, nj = kind.shape[0], marker_joint.shape[0], states.shape[1], parent.shape[0]
    seen = np.ones((nv, nm), np.bool_)
    cs, sn = np.empty(na), np.empty(na)
    rot, pos = np.empty((nj, 3, 3)), np.empty((nj, 3))
    mk, proj = np.empty((nm, 3)), np.empty((nv, nm, 2))
    for k in range(states.shape[0]):
        if ran[k]:
            project_posture(states[k], root_pos[k], root_rot[k], parent, chain, pre_rot,
                            pre_trans, post_trans, elem_axis, elem_index, joint_flags,
                            marker_joint, marker_local, slide_index, kind, P, K, dist, R, t,
                            cs, sn, rot, pos, mk, proj)
            unexplained[k] = nearest_residuals(proj, points, offsets[k * nv: (k + 1) * nv + 1],
                                               seen, gate, out[k])


@njit(cache=True, nogil=True, inline="always")
def observed(objective, view_off, obs3):
    """Whether a frame has anything to fit: a detection in some view (``view_off``, its
    views' offsets), or for 3D points and clouds a point of weight > 0 (``obs3``)."""
    if objective in (OBJ_POINTS3D, OBJ_CLOUD):
        has = False
        for i in range(obs3.shape[0]):
            has = has or obs3[i, 3] > 0.0
        return has
    return view_off[view_off.shape[0] - 1] > view_off[0]


@njit(cache=True, nogil=True, inline="always")
def evaluate(objective, proj, mk, points, conf, view_off, obs3, bidirectional, weight, cap,
             penalty_cap, one, per_view, nearest):
    """E of projected (``proj``) and 3D (``mk``) markers under ``objective``; fills
    ``per_view`` (zeros for 3D points, which have no views)."""
    if objective == OBJ_NEAREST:
        return projection_error(proj, points, view_off, obs3, bidirectional, weight, cap,
                                penalty_cap, one, per_view, nearest)
    if objective == OBJ_LABELLED:
        return labelled_error(proj, points, conf, view_off, cap, per_view)
    per_view[:] = 0.0
    if objective == OBJ_CLOUD:
        return cloud_error(mk, obs3, 0, mk.shape[0], NO_CLAIMS, weight if bidirectional
                           else 0.0, cap, penalty_cap, one, nearest)
    return points3d_error(mk, obs3, cap)



@njit(cache=True, nogil=True)
def partition_error(objective, proj, mk, points, conf, view_off, obs3, cap, m0, m1, claimed,
                    penalty, penalty_cap, one, nearest):
    """E of the markers ``m0:m1`` only (one partition; the rest is constant while it moves).

    Unlabelled points: each marker's nearest detection among those not ``claimed`` by the
    markers of other partitions (:func:`claim_detections`), capped: a leg cannot take a
    neighbour's marker. With ``penalty > 0`` (the bidirectional modes) each unclaimed
    detection that none of these markers takes adds ``penalty · min(distance to the nearest
    of them, penalty_cap)``: a leg is pulled to explain the blobs left over, not to share
    another's. Labelled keypoints and 3D points: each marker against its own, as
    :func:`labelled_error` and :func:`points3d_error`. With ``one`` each detection (point)
    explains at most one of these markers (:func:`one_to_one`). A marker hidden in a view
    (:func:`hidden_in`) is left out of it. ``nearest`` (n_markers,) is scratch.
    """
    missing = cap if cap < np.inf else NAN_MARKER_COST
    total = 0.0
    if objective == OBJ_CLOUD:
        return cloud_error(mk, obs3, m0, m1, claimed, penalty, cap, penalty_cap, one,
                           nearest)
    if objective == OBJ_POINTS3D:
        for i in range(m0, m1):
            w = obs3[i, 3]
            if w > 0.0:
                dx = mk[i, 0] - obs3[i, 0]
                dy = mk[i, 1] - obs3[i, 1]
                dz = mk[i, 2] - obs3[i, 2]
                total += w * min(math.sqrt(dx * dx + dy * dy + dz * dz), cap)
        return total
    nm = proj.shape[1]
    for v in range(proj.shape[0]):
        a = view_off[v]
        b = view_off[v + 1]
        if b <= a:
            continue
        if objective == OBJ_LABELLED:
            if b - a == nm:
                for i in range(m0, m1):
                    w = conf[a + i]
                    if w > 0.0 and math.isfinite(points[a + i, 0]):
                        dx = proj[v, i, 0] - points[a + i, 0]
                        dy = proj[v, i, 1] - points[a + i, 1]
                        d = math.sqrt(dx * dx + dy * dy)
                        total += w * min(d if math.isfinite(d) else missing, cap)
            continue
        ev = 0.0
        n_seen = 0
        for i in range(m0, m1):
            if hidden_in(obs3, i, v):
                nearest[i] = UNSEEN
                continue
            n_seen += 1
            best, arg = nearest_in_view(proj[v, i, 0], proj[v, i, 1], points, a, b, claimed)
            nearest[i] = arg
            d = math.sqrt(best) if best < np.inf else missing
            ev += min(d, cap)
        if one:
            ev = one_to_one(proj[v], points, a, b, m0, m1, False, claimed, cap, nearest)
        total += ev
        if penalty > 0.0 and n_seen == 0:  # no marker of these in the view: each costs missing
            for c in range(a, b):
                total += 0.0 if claimed[c] else penalty * min(missing, penalty_cap)
        elif penalty > 0.0:
            for c in range(a, b):
                taken = claimed[c]
                best = np.inf
                for i in range(m0, m1):
                    taken = taken or takes(nearest[i], c)
                    dx = proj[v, i, 0] - points[c, 0]
                    dy = proj[v, i, 1] - points[c, 1]
                    seen = nearest[i] != UNSEEN
                    best = min(best, dx * dx + dy * dy) if seen else best
                if not taken:
                    total += penalty * min(math.sqrt(best), penalty_cap)
    return total


@njit(cache=True, nogil=True)
def count_unexplained(proj, points, view_off, obs3, gate):
    """Detections farther than ``gate`` pixels from every projected model marker not hidden
    in their view (:func:`hidden_in`)."""
    g2 = gate * gate
    n = 0
    for v in range(proj.shape[0]):
        for c in range(view_off[v], view_off[v + 1]):
            near = False
            for i in range(proj.shape[1]):
                dx = proj[v, i, 0] - points[c, 0]
                dy = proj[v, i, 1] - points[c, 1]
                near = near or (dx * dx + dy * dy <= g2 and not hidden_in(obs3, i, v))
            n += 0 if near else 1
    return n


@njit(cache=True, nogil=True)
def claim_detections(proj, points, view_off, obs3, claimers, gate, claimed):
    """Mark the detections that the markers flagged in ``claimers`` (n_markers,) explain:
    each such marker's nearest detection in each view, if within ``gate`` pixels (a marker
    far from every detection, e.g. occluded, or hidden in the view, claims nothing)."""
    claimed[:] = False
    g2 = gate * gate
    for v in range(proj.shape[0]):
        a = view_off[v]
        b = view_off[v + 1]
        for i in range(proj.shape[1]):
            if not claimers[i] or hidden_in(obs3, i, v):
                continue
            best = g2
            arg = -1
            for c in range(a, b):
                dx = proj[v, i, 0] - points[c, 0]
                dy = proj[v, i, 1] - points[c, 1]
                d2 = dx * dx + dy * dy
                if d2 <= best:
                    best = d2
                    arg = c
            if arg >= 0:
                claimed[arg] = True


@njit(cache=True, nogil=True)
def posture_error(angles, root_pos, root_rot, parent, chain, pre_rot, pre_trans, post_trans,
                  elem_axis, elem_index, joint_flags, marker_joint, marker_local, slide_index,
                  kind, P, K, dist, R, t, objective, points, conf, view_off, obs3,
                  bidirectional, weight, cap, penalty_cap, one, per_view):
    """E (Eq. 5, a variant or another objective, :func:`evaluate`) of one posture ``angles``
    (n_state,); fills ``per_view`` (n_views,). Allocates its scratch: for single evaluations,
    not for loops."""
    na = angles.shape[0]
    nj = parent.shape[0]
    nm = marker_joint.shape[0]
    cs = np.empty(na)
    sn = np.empty(na)
    rot = np.empty((nj, 3, 3))
    pos = np.empty((nj, 3))
    mk = np.empty((nm, 3))
    proj = np.empty((kind.shape[0], nm, 2))
    nearest = np.empty(nm, np.int64)
    project_posture(angles, root_pos, root_rot, parent, chain, pre_rot, pre_trans, post_trans,
                    elem_axis, elem_index, joint_flags, marker_joint, marker_local, slide_index,
                    kind, P, K, dist, R, t, cs, sn, rot, pos, mk, proj)
    return evaluate(objective, proj, mk, points, conf, view_off, obs3, bidirectional, weight,
                    cap, penalty_cap, one, per_view, nearest)


# -- simulated annealing (Sect. 2.3, Eq. 6) ----------------------------------------------
@njit(cache=True, nogil=True)
def anneal_chain(start, free_idx, step, hist, nbins, th, dof_kind, lo, hi, max_redraws,
                 n_end, n_l, n_tau, tau0, l0, c_l, c_tau, eps, state,
                 root_pos, root_rot, parent, chain, pre_rot, pre_trans, post_trans, elem_axis,
                 elem_index, joint_flags, marker_joint, marker_local, slide_index, kind, P, K,
                 dist, R, t,
                 objective, points, conf, view_off, obs3, bidirectional, weight, cap,
                 penalty_cap, one, j0, j1, m0, m1, claimed,
                 cur, cand, best, cs, sn, rot, pos, mk, proj, per_view, nearest, d2):
    """One annealing run from ``start``; the best posture seen is left in ``best``.

    Each iteration draws ``j' = j + l·v`` with ``v_i = s(H_i)·r_i``, ``r_i ~ U[-1, 1]``
    (Eq. 6) for the free axes ``free_idx`` in order (histogram entries first, then range
    entries); ``r_i`` is redrawn while
    ``H_i(j'_i) < th`` (for entries of ``dof_kind`` DOF_RANGE: while outside
    ``[lo_i, hi_i]``), at most ``max_redraws`` times, after which axis i stays where it is
    for this iteration. A draw ``u`` made first in each iteration decides acceptance by the
    Metropolis criterion at temperature τ: always if E does not grow, else if
    ``ΔE < -τ·log(u)``, i.e. ``u < exp(-ΔE/τ)``. τ is multiplied by ``c_tau`` every ``n_tau``
    iterations and l by ``c_l`` every ``n_l``. Stops after ``n_end`` iterations or once the
    best ``E < eps``.

    Parameters
    ----------
    start : (n_axes,) radians; locked axes hold their value and are never changed.
    free_idx : (n_free,) int64; step : (n_axes,) s(H_i) in radians.
    hist : (n_axes, n_bins_max), nbins : (n_axes,) int64 histogram tables.
    state : uint64 start state of the random stream (:func:`stream_state`).
    j0, j1, m0, m1 : the joints and markers the moved entries reach (a partition's subtree;
        ``0, nj, 0, nm`` for the whole body). With a partition, E is :func:`partition_error`
        of its markers ``m0:m1`` (detections ``claimed`` by other partitions excluded), and
        ``rot``, ``pos``, ``mk``, ``proj`` must hold the current posture of the rest.
    cur, cand, best, cs, sn : (n_axes,) scratch; rot (nj, 3, 3), pos (nj, 3), mk (nm, 3),
    proj (n_views, n_markers, 2), per_view (n_views,), nearest (n_markers,) int64 scratch;
    d2 (n_markers + cloud rows,) float scratch of :func:`cloud_error_once` for a cloud
    (shorter, e.g. empty: :func:`cloud_error` instead).

    Returns
    -------
    best_error : float
    iterations : int
    """
    n_free = free_idx.shape[0]
    n_hist = 0  # free_idx holds the DOF_HISTOGRAM entries first
    while n_hist < n_free and dof_kind[free_idx[n_hist]] == DOF_HISTOGRAM:
        n_hist += 1
    kind = _drawn_views(kind, objective)
    any_pinhole = _has_pinhole(kind)
    marks = obs3  # hidden marks not projected (3D objectives read no projection)
    rs = np.uint64(state)  # the stream state; int64 arithmetic with uint64 would be float
    for k in range(start.shape[0]):
        cur[k] = start[k]
        cand[k] = start[k]
        best[k] = start[k]
        sn[k], cs[k] = sincos(start[k])
    whole = j0 == 0 and j1 == parent.shape[0] and m0 == 0 and m1 == marker_joint.shape[0]
    span = (j0, j1, m0, m1)
    unexplained = weight if bidirectional else 0.0  # the partition's unexplained-blob weight
    # a cloud with nothing claimed (a partition's comes without the claimed points): each
    # distance computed once (cloud_error_once), the same E
    once = objective == OBJ_CLOUD and not one and (whole or claimed.shape[0] == 0) and \
        d2.shape[0] >= mk.shape[0] + obs3.shape[0]
    marker_d2 = d2[:mk.shape[0]]
    point_d2 = d2[mk.shape[0]:]
    _project_cs(cand, cs, sn, root_pos, root_rot, parent, chain, pre_rot, pre_trans,
                post_trans, elem_axis, elem_index, joint_flags, marker_joint, marker_local,
                slide_index, kind, P, K, dist, R, t, rot, pos, mk, proj, any_pinhole, span,
                marks)
    if not whole:
        e_cur = partition_error(objective, proj, mk, points, conf, view_off, obs3, cap, m0,
                                m1, claimed, unexplained, penalty_cap, one, nearest)
    else:
        e_cur = evaluate(objective, proj, mk, points, conf, view_off, obs3, bidirectional,
                         weight, cap, penalty_cap, one, per_view, nearest)
    e_best = e_cur
    tau = tau0
    length = l0
    to_tau = n_tau  # countdowns: two integer modulos per iteration cost more than these
    to_l = n_l
    it = 0
    done = e_best < eps
    while it < n_end and not done:
        # Metropolis (Kirkpatrick et al. 1983): accept if u < exp(-ΔE/τ), i.e. if
        # ΔE < τ·(-log u). The draw and its logarithm come first, off the iteration's
        # critical path (candidate -> kinematics -> E -> acceptance).
        rs, u = next_uniform(rs)
        e_accept = e_cur + tau * -log_unit(u)
        # Histogram-checked angles first, then range-checked entries (free_idx lists them
        # in that order): two loops keep the kind test out of the redraw loop.
        for q in range(n_hist):
            i = free_idx[q]
            scale = length * step[i]
            ok = False
            tries = 0
            x = cur[i]
            while not ok and tries <= max_redraws:
                rs, u = next_uniform(rs)
                x = cur[i] + scale * (2.0 * u - 1.0)
                ok = hist_at(hist, nbins, i, x) >= th
                tries += 1
            x = x if ok else cur[i]
            cand[i] = x
            sn[i], cs[i] = sincos(x)
        for q in range(n_hist, n_free):
            i = free_idx[q]
            scale = length * step[i]
            ok = False
            tries = 0
            x = cur[i]
            while not ok and tries <= max_redraws:
                rs, u = next_uniform(rs)
                x = cur[i] + scale * (2.0 * u - 1.0)
                ok = lo[i] <= x and x <= hi[i]
                tries += 1
            x = x if ok else cur[i]
            cand[i] = x
            sn[i], cs[i] = sincos(x)
        _project_cs(cand, cs, sn, root_pos, root_rot, parent, chain, pre_rot, pre_trans,
                    post_trans, elem_axis, elem_index, joint_flags, marker_joint, marker_local,
                    slide_index, kind, P, K, dist, R, t, rot, pos, mk, proj, any_pinhole, span,
                    marks)
        if once:
            e = cloud_error_once(mk, obs3, m0, m1, unexplained, cap, penalty_cap, nearest,
                                 marker_d2, point_d2)
        elif not whole:
            e = partition_error(objective, proj, mk, points, conf, view_off, obs3, cap, m0,
                                m1, claimed, unexplained, penalty_cap, one, nearest)
        elif objective == OBJ_NEAREST and not bidirectional and not one and \
                obs3.shape[0] == 0:  # the paper's case: no marker marked hidden
            e = _paper_error(proj, points, view_off, cap)
        else:
            e = evaluate(objective, proj, mk, points, conf, view_off, obs3, bidirectional,
                         weight, cap, penalty_cap, one, per_view, nearest)
        if e <= e_cur or e < e_accept:
            e_cur = e
            for q in range(n_free):
                cur[free_idx[q]] = cand[free_idx[q]]
            if e < e_best:
                e_best = e
                for q in range(n_free):
                    best[free_idx[q]] = cand[free_idx[q]]
        it += 1
        to_tau -= 1
        if to_tau == 0:
            tau *= c_tau
            to_tau = n_tau
        to_l -= 1
        if to_l == 0:
            length *= c_l
            to_l = n_l
        done = e_best < eps
    return e_best, it


#: Postures the start search keeps from one stage to the next (its beam width).
BEAM = 32


@njit(cache=True, nogil=True)
def beam_start(work, s0, s1, stage_dof_off, stage_dofs, stage_mark, stage_joint, n_samples,
               state, hist,
               nbins, th, dof_kind, lo, hi, rp, rr, parent, chain, pre_rot, pre_trans,
               post_trans, elem_axis, elem_index, joint_flags, marker_joint, marker_local,
               slide_index, kind, P, K, dist, R, t, objective, points, conf, view_off, obs3,
               cap, j0, j1, m0, m1, claimed, penalty_cap, one, refine_steps, refine_gate, cs,
               sn, rot, pos, mk, proj, nearest):
    """A partition's start posture by a beam search along its joints, into ``work``.

    Stage ``s`` (``s0:s1``, one joint's entries, root first) draws ``BEAM · n_samples``
    values for its entries, spread over the postures kept so far — each entry uniform in
    ``[lo, hi]``, a histogram angle redrawn (at most 16 times) while implausible — and keeps
    the ``BEAM`` postures with the lowest :func:`partition_error` of the markers the stage
    places (``m0:stage_mark[s]``, at most ``m1``; detections ``claimed`` by other partitions
    left out), each kept posture's undrawn values counting too. Joint by joint the search
    follows the limb outward along its own markers, so annealing starts in the right basin
    where the start posture lies nearer another limb's markers. ``rot`` … ``proj`` must
    hold the current posture of the rest of the body. With ``refine_steps`` the best
    posture is polished by Levenberg-Marquardt at the end. Returns the E of the partition's
    markers at the best posture before that polish."""
    ns = work.shape[0]
    e_first = np.inf
    kind = _drawn_views(kind, objective)
    any_pinhole = _has_pinhole(kind)
    marks = obs3  # hidden marks not projected (3D objectives read no projection)
    cloud, free = obs3, claimed  # what the draws are scored against
    if objective == OBJ_CLOUD:
        cloud, free = unclaimed_cloud(obs3, claimed)
    rs = state
    beams = np.empty((BEAM, ns))
    beams[0, :] = work
    nb = 1
    most = BEAM * (n_samples + 1) * 2
    cands = np.empty((most, ns))
    cand_e = np.empty(most)
    for st in range(s0, s1):
        d0 = stage_dof_off[st]
        d1 = stage_dof_off[st + 1]
        m_end = min(stage_mark[st], m1)
        # A stage's entries move no marker before its first (stages are grouped so), and
        # nothing before its first joint: a draw recomputes only those joints and markers
        # and adds their E to the beam's, which is computed once per beam. With one-to-one
        # the markers' costs are not separable, so every draw scores them all.
        ms = m0 if (st == s0 or one) else min(stage_mark[st - 1], m_end)
        jf = j0 if one else stage_joint[st]
        je = jf  # one past the last joint that carries a marker the stage places
        for m in range(ms, m_end):
            je = max(je, marker_joint[m] + 1)
        span = (j0, j1, m0, ms)
        span_new = (jf, je, ms, m_end)
        draws = (BEAM * n_samples) // nb
        nc = 0
        for b in range(nb):
            for k in range(ns):
                sn[k], cs[k] = sincos(beams[b, k])
            # The beam's posture (the joints before the stage's first stay so for its
            # draws) and the E of the markers earlier stages placed
            _project_cs(beams[b], cs, sn, rp, rr, parent, chain, pre_rot, pre_trans,
                        post_trans, elem_axis, elem_index, joint_flags, marker_joint,
                        marker_local, slide_index, kind, P, K, dist, R, t, rot, pos, mk, proj,
                        any_pinhole, span, marks)
            e_beam = 0.0
            if ms > m0:
                e_beam = partition_error(objective, proj, mk, points, conf, view_off, cloud,
                                         cap, m0, ms, free, 0.0, penalty_cap, one, nearest)
            for smp in range(draws + 1):
                cands[nc, :] = beams[b]
                if smp > 0:  # draw 0 keeps the beam's own values
                    for q in range(d0, d1):
                        i = stage_dofs[q]
                        ok = False
                        tries = 0
                        x = beams[b, i]
                        while not ok and tries < 16:
                            rs, u = next_uniform(rs)
                            x = lo[i] + (hi[i] - lo[i]) * u
                            ok = dof_kind[i] != DOF_HISTOGRAM or hist_at(hist, nbins, i, x) >= th
                            tries += 1
                        cands[nc, i] = x
                for q in range(d0, d1):
                    i = stage_dofs[q]
                    sn[i], cs[i] = sincos(cands[nc, i])
                _project_cs(cands[nc], cs, sn, rp, rr, parent, chain, pre_rot, pre_trans,
                            post_trans, elem_axis, elem_index, joint_flags, marker_joint,
                            marker_local, slide_index, kind, P, K, dist, R, t, rot, pos, mk,
                            proj, any_pinhole, span_new, marks)
                cand_e[nc] = e_beam + partition_error(objective, proj, mk, points, conf,
                                                      view_off, cloud, cap, ms, m_end, free,
                                                      0.0, penalty_cap, one, nearest)
                nc += 1
        # Keep the best BEAM. Keeping at most 4 per distinct match (which point each placed
        # marker takes) starved the stages whose entries the placed markers do not fix (a
        # coxa's roll about its own axis, then the femur's): the fly's runs agreed in 44 %
        # against 73 % (docs/benchmarks.md, "The start search keeps its best").
        order = np.argsort(cand_e[:nc])
        e_first = cand_e[order[0]]
        nb = min(BEAM, nc)
        for b in range(nb):
            beams[b, :] = cands[order[b]]
    # Only the best is polished: polishing every kept posture after each stage (32 per joint)
    # was half of a fly run's cost besides annealing, and measured no better (docs/benchmarks.md)
    if refine_steps > 0 and s1 > s0:
        _rk.refine_posture(beams[0], stage_dofs[stage_dof_off[s0]:stage_dof_off[s1]], lo, hi,
                           dof_kind, refine_steps, refine_gate, rp, rr, parent, chain,
                           pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
                           marker_joint, marker_local, slide_index, kind, P, K, dist, R, t,
                           objective, points, conf, view_off, obs3)
    work[:] = beams[0]
    return e_first


@njit(cache=True, nogil=True)
def anneal_partitions(origin, state, rp, rr, body, cams, dofs, schedule, error, objective,
                      points, conf, view_off, obs3, parts, claimed, work, cur, cand, best, cs,
                      sn, rot, pos, mk, proj, per_view, nearest):
    """One annealing run over partitions, each in turn (partitioned sampling): partition p
    moves only its own entries, with its share of ``schedule`` (N_end, N_l and N_tau times
    its share of the free entries, at least 1: a round anneals about N_end), scored by
    :func:`partition_error` of the markers it reaches (in the first round a trunk by its own
    markers only: its limbs are not fitted yet). The first round fits every partition
    against all detections; later rounds (``rounds`` > 1) exclude the detections that the
    other partitions' markers explain (:func:`claim_detections` within ``claim_gate`` px),
    so limbs do not share or take each other's markers. With ``samples`` > 0 each partition
    of the first round starts from a beam search along its joints (:func:`beam_start`) and
    may not use the detections that the partitions fitted before it explain. Leaves the
    result in ``best``.

    Returns
    -------
    error : float, E of the whole posture (:func:`evaluate`)
    iterations : int, summed over partitions and rounds
    """
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = body
    kind, P, K, dist, R, t = cams
    _, step, hist, nbins, dof_kind, lo, hi = dofs
    (th, max_redraws, n_end, n_l, n_tau, tau0, l0, c_l, c_tau, eps, _, _, _, _, _, _,
     _, _) = schedule
    bidirectional, weight, cap, penalty_cap, one = error
    (bounds, part_off, part_dofs, rounds, claim_gate, samples, stage_off, stage_dof_off,
     stage_dofs, stage_mark, stage_joint, _) = parts
    work[:] = origin
    its = 0
    rs = np.uint64(state)
    claimers = np.zeros(marker_joint.shape[0], np.bool_)
    n_parts = bounds.shape[0]
    order = np.arange(n_parts)
    limbs_only = n_parts > 1
    for p in range(n_parts):
        limbs_only = limbs_only and bounds[p, 4] >= bounds[p, 3]
    ordered = samples > 0 and limbs_only
    found = np.empty((n_parts if ordered else 0, work.shape[0]))  # each limb's own search
    unclaimed = np.zeros(claimed.shape[0] if ordered else 0, np.bool_)
    if ordered:
        # Limbs on roots of their own (no trunk to fit first): each searches its start
        # without claims, and the clearest (lowest E per marker) go first and claim their
        # points, so a limb that happens to come first cannot take a clearer one's.
        project_posture(work, rp, rr, parent, chain, pre_rot, pre_trans, post_trans,
                        elem_axis, elem_index, joint_flags, marker_joint, marker_local,
                        slide_index, kind, P, K, dist, R, t, cs, sn, rot, pos, mk, proj)
        claimed[:] = False
        clear = np.empty(n_parts)
        for p in range(n_parts):
            cur[:] = work
            rs, _ = next_uniform(rs)
            clear[p] = beam_start(
                cur, stage_off[p], stage_off[p + 1], stage_dof_off, stage_dofs, stage_mark,
                stage_joint,
                samples, mix64(rs ^ _GOLDEN), hist, nbins, th, dof_kind, lo, hi, rp, rr,
                parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index,
                joint_flags, marker_joint, marker_local, slide_index, kind, P, K, dist, R, t,
                objective, points, conf, view_off, obs3, cap, bounds[p, 0], bounds[p, 1],
                bounds[p, 2], bounds[p, 3], claimed, penalty_cap, one, schedule[13],
                schedule[14], cs, sn, rot, pos, mk, proj, nearest) / max(
                    1, bounds[p, 3] - bounds[p, 2])
            found[p, :] = cur
        order = np.argsort(clear)
    for r in range(rounds):
        for k in range(n_parts):
            p = order[k] if r == 0 else k
            project_posture(work, rp, rr, parent, chain, pre_rot, pre_trans, post_trans,
                            elem_axis, elem_index, joint_flags, marker_joint, marker_local,
                            slide_index, kind, P, K, dist, R, t, cs, sn, rot, pos, mk, proj)
            j0, j1, m0, m1 = bounds[p, 0], bounds[p, 1], bounds[p, 2], bounds[p, 3]
            if r == 0 and bounds[p, 4] > m0:
                m1 = bounds[p, 4]  # a trunk before its limbs are fitted: its own markers
            claimers[:] = False
            if r > 0:  # every other partition claims
                claimers[:] = True
                claimers[m0:m1] = False
            elif samples > 0:  # the partitions fitted before this one claim
                for q in order[:k]:
                    claimers[bounds[q, 2]:bounds[q, 4]] = True
            if objective == OBJ_NEAREST:
                claim_detections(proj, points, view_off, obs3, claimers, claim_gate,
                                 claimed)
            elif objective == OBJ_CLOUD:
                claim_cloud(mk, obs3, claimers, claim_gate, claimed)
            else:
                claimed[:] = False
            rs, _ = next_uniform(rs)  # a stream of its own for each partition and round
            dofs_p = part_dofs[part_off[p]:part_off[p + 1]]
            searched = False
            if r == 0 and ordered:
                # the limb's own search stands unless a clearer limb claimed its points
                for q in range(dofs_p.shape[0]):
                    work[dofs_p[q]] = found[p, dofs_p[q]]
                project_posture(work, rp, rr, parent, chain, pre_rot, pre_trans, post_trans,
                                elem_axis, elem_index, joint_flags, marker_joint, marker_local,
                                slide_index, kind, P, K, dist, R, t, cs, sn, rot, pos, mk, proj)
                searched = partition_error(
                    objective, proj, mk, points, conf, view_off, obs3, cap, m0, m1, claimed,
                    0.0, penalty_cap, one, nearest) == partition_error(
                    objective, proj, mk, points, conf, view_off, obs3, cap, m0, m1, unclaimed,
                    0.0, penalty_cap, one, nearest)
            if r == 0 and samples > 0 and not searched:
                beam_start(work, stage_off[p], stage_off[p + 1], stage_dof_off, stage_dofs,
                           stage_mark, stage_joint, samples, mix64(rs ^ _GOLDEN), hist,
                           nbins, th,
                           dof_kind, lo, hi, rp, rr, parent, chain, pre_rot, pre_trans,
                           post_trans, elem_axis, elem_index, joint_flags, marker_joint,
                           marker_local, slide_index, kind, P, K, dist, R, t, objective,
                           points, conf, view_off, obs3, cap, j0, j1, m0, m1, claimed,
                           penalty_cap, one, schedule[13], schedule[14], cs, sn, rot, pos, mk,
                           proj, nearest)
            cloud, free = obs3, claimed
            if objective == OBJ_CLOUD:  # the same E, without the claimed points
                cloud, free = unclaimed_cloud(obs3, claimed)
            # the run's schedule shared by axes: a round anneals about N_end in all
            share = dofs_p.shape[0] / max(1, part_dofs.shape[0])
            _, n = anneal_chain(work, dofs_p, step, hist,
                                nbins, th, dof_kind, lo, hi, max_redraws,
                                max(1, round(n_end * share)), max(1, round(n_l * share)),
                                max(1, round(n_tau * share)),
                                tau0, l0, c_l, c_tau, eps, mix64(rs), rp, rr, parent, chain,
                                pre_rot, pre_trans, post_trans, elem_axis, elem_index,
                                joint_flags, marker_joint, marker_local, slide_index, kind, P,
                                K, dist, R, t, objective, points, conf, view_off, cloud,
                                bidirectional, weight, cap, penalty_cap, one, j0, j1, m0,
                                m1, free, cur, cand, best, cs, sn, rot, pos, mk, proj,
                                per_view, nearest, np.empty(mk.shape[0] + cloud.shape[0]))
            its += n
            work[:] = best
    project_posture(work, rp, rr, parent, chain, pre_rot, pre_trans, post_trans, elem_axis,
                    elem_index, joint_flags, marker_joint, marker_local, slide_index, kind, P,
                    K, dist, R, t, cs, sn, rot, pos, mk, proj)
    best[:] = work
    return evaluate(objective, proj, mk, points, conf, view_off, obs3, bidirectional, weight,
                    cap, penalty_cap, one, per_view, nearest), its


# -- the per-frame procedure, shared by fit_frames and the lane kernel ---------------------
@njit(cache=True, nogil=True)
def clear_frame(out, f):
    """Frame ``f``'s outputs before it is fitted: NaN, no runs (a frame without observations
    keeps them)."""
    out.runs[f] = 0
    out.iterations[f] = 0
    out.pairs[f] = 0
    out.error[f] = np.nan
    out.angles[f, :] = np.nan
    out.view_error[f, :] = np.nan
    out.run_angles[f, :, :] = np.nan
    out.run_error[f, :] = np.nan


@njit(cache=True, nogil=True, inline="always")
def wants_run(run, min_runs, max_runs, e_keep, u_keep, threshold, max_unexplained):
    """Whether a frame gets run ``run``: the first ``min_runs`` always (candidates), then
    while the kept run is above the re-analysis threshold or leaves too many detections
    unexplained, ``max_runs`` at most."""
    u_limit = max_unexplained if max_unexplained >= 0 else 1 << 30
    return run < max_runs and (run < min_runs or not (e_keep <= threshold
                                                      and u_keep <= u_limit))


@njit(cache=True, nogil=True, inline="always")
def keeps(e, u, e_keep, u_keep, max_unexplained):
    """Whether a run (E ``e``, ``u`` unexplained detections) replaces the kept one: lower E,
    or with ``max_unexplained`` in use fewer unexplained detections first; ties keep the
    earlier run."""
    if max_unexplained < 0:
        return e < e_keep
    return u < u_keep or (u == u_keep and e < e_keep)


@njit(cache=True, nogil=True)
def take_runs(out, f, issued, run_u, run_pairs, max_unexplained):
    """Frame ``f``'s first ``issued`` runs taken in run order, as :func:`fit_frames` takes
    them after each (``run_u``, ``run_pairs``: each run's unexplained detections and
    refinement pairs): the kept run's (E, unexplained, index); its pairs go into
    ``out.pairs[f]``. For the backends that finish a frame's runs out of order."""
    e_keep, u_keep, kept = np.inf, 1 << 30, 0
    for r in range(issued):
        if keeps(out.run_error[f, r], run_u[r], e_keep, u_keep, max_unexplained):
            e_keep, u_keep, kept = out.run_error[f, r], run_u[r], r
            out.pairs[f] = run_pairs[r]
    return e_keep, u_keep, kept


@njit(cache=True, nogil=True, inline="always")
def same_markers(a, b, tol):
    """Whether every marker of ``a`` (n, 3) lies within ``tol`` of its place in ``b``."""
    same = True
    for i in range(a.shape[0]):
        dx = a[i, 0] - b[i, 0]
        dy = a[i, 1] - b[i, 1]
        dz = a[i, 2] - b[i, 2]
        same = same and dx * dx + dy * dy + dz * dz <= tol * tol
    return same


@njit(cache=True, nogil=True)
def finish_run(best, e, rp, rr, body, cams, dofs, schedule, error, objective, points, conf,
               view_off, obs3, claim_gate, annealed, cs, sn, rot, pos, mk, proj, per_view,
               nearest):
    """After a run's annealing (best posture ``best``, its E ``e``): refinement, kept only if
    E did not grow, and the count of unexplained detections. Updates ``best`` in place;
    returns (E, refinement pairs, unexplained)."""
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = body
    kind, P, K, dist, R, t = cams
    free_idx, _, _, _, dof_kind, lo, hi = dofs
    refine_steps, refine_gate, max_unexplained = schedule[13], schedule[14], schedule[16]
    bidirectional, weight, cap, penalty_cap, one = error
    pairs = 0
    if refine_steps > 0:
        # Refinement minimises squared pair residuals, not E: keep its result only if E
        # did not grow (it never makes a fit worse).
        annealed[:] = best
        _, pairs = _rk.refine_posture(
            best, free_idx, lo, hi, dof_kind, refine_steps, refine_gate, rp, rr, parent, chain,
            pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags, marker_joint,
            marker_local, slide_index, _drawn_views(kind, objective), P, K, dist, R, t,
            objective, points, conf, view_off, obs3)
        project_posture(best, rp, rr, parent, chain, pre_rot, pre_trans, post_trans,
                        elem_axis, elem_index, joint_flags, marker_joint, marker_local,
                        slide_index, kind, P, K, dist, R, t, cs, sn, rot, pos, mk, proj)
        e_refined = evaluate(objective, proj, mk, points, conf, view_off, obs3, bidirectional,
                             weight, cap, penalty_cap, one, per_view, nearest)
        if e_refined <= e:
            e = e_refined
        else:
            best[:] = annealed
            pairs = 0
    u = 0
    if max_unexplained >= 0 and objective == OBJ_NEAREST:
        # Detections far from every model marker: a limb on another's blobs leaves its own
        # unexplained, a fused blob does not.
        project_posture(best, rp, rr, parent, chain, pre_rot, pre_trans, post_trans,
                        elem_axis, elem_index, joint_flags, marker_joint, marker_local,
                        slide_index, kind, P, K, dist, R, t, cs, sn, rot, pos, mk, proj)
        u = count_unexplained(proj, points, view_off, obs3, claim_gate)
    elif max_unexplained >= 0 and objective == OBJ_CLOUD:
        project_posture(best, rp, rr, parent, chain, pre_rot, pre_trans, post_trans,
                        elem_axis, elem_index, joint_flags, marker_joint, marker_local,
                        slide_index, kind, P, K, dist, R, t, cs, sn, rot, pos, mk, proj)
        u = count_unexplained_cloud(mk, obs3, claim_gate)
    return e, pairs, u


@njit(cache=True, nogil=True)
def write_frame(out, f, keep, runs, rp, rr, body, cams, error, objective, points, conf,
                view_off, obs3, cs, sn, rot, pos, mk, proj, per_view, nearest):
    """Frame ``f``'s outputs from its kept posture ``keep`` after ``runs`` runs."""
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = body
    kind, P, K, dist, R, t = cams
    bidirectional, weight, cap, penalty_cap, one = error
    project_posture(keep, rp, rr, parent, chain, pre_rot, pre_trans, post_trans, elem_axis,
                    elem_index, joint_flags, marker_joint, marker_local, slide_index, kind, P,
                    K, dist, R, t, cs, sn, rot, pos, mk, proj)
    out.error[f] = evaluate(objective, proj, mk, points, conf, view_off, obs3, bidirectional,
                            weight, cap, penalty_cap, one, per_view, nearest)
    out.view_error[f, :] = per_view
    out.angles[f, :] = keep
    out.runs[f] = runs


@njit(cache=True, nogil=True, parallel=True)
def fit_frames(seg_off, frame_ids, root_pos, root_rot, start, body, cams, dofs, schedule,
               error, obs, parts, out):
    """Fit many frames in parallel (``prange`` over segments of consecutive frames).

    Frames ``seg_off[s]:seg_off[s + 1]`` form segment ``s``, fitted in order by one thread;
    segments are independent. With ``start_previous`` a frame's first run starts from the
    previous frame's result in its segment (the segment's first frame from ``start``);
    otherwise every run starts from ``start``. Re-runs always start from ``start``. With
    ``refine_steps > 0`` each run's best posture is polished by
    :func:`kinematics._kernels.refine.refine_posture` (pairs within ``refine_gate`` pixels,
    axis ranges ``lo``, ``hi`` in radians) before it is scored. A frame whose error exceeds
    ``reanalysis_threshold`` is fitted again on the random stream of the next run index
    (Table 1 note), ``max_runs`` runs at most; the run with the lowest error is kept.

    Parameters (the namedtuples are defined in :mod:`kinematics.fit.problem`)
    ----------
    seg_off : (n_segments + 1,) int64; frame_ids : (n,) int64 frame numbers (seed streams).
    root_pos : (n, n_chains, 3); root_rot : (n, n_chains, 3, 3) seed rotations of free roots
        (identity otherwise); start : (n_state,) radians (lengths for translation entries).
    body : FoldedBody; cams : CameraArrays.
    dofs : DofArrays (free_idx, step, hist, nbins, dof_kind, lo, hi).
    schedule : Schedule (Table 1 and the fitter's own settings, ``start_previous``).
    error : ErrorArgs (bidirectional, weight, cap, penalty_cap).
    obs : ObservationArrays (objective: OBJ_NEAREST, OBJ_LABELLED or OBJ_POINTS3D; points
        (n_points, 2); conf (n_points,) weights of labelled keypoints; offsets (n * n_views +
        1,) frame-major; points3d (n, n_markers or 0, 4)).
    parts : Partitions (bounds (n_parts, 5): joints j0:j1 and markers m0:m1 each partition
        reaches, m0:m_own its own markers; dof_off/dofs its free entries; rounds;
        claim_gate): one partition anneals the whole body at once (the paper); more are
        annealed in turn
        (:func:`anneal_partitions`).
    out : FitOutputs: angles (n, n_state), NaN for frames without any observation; error
        (n,); view_error (n, n_views); runs, iterations (n,) int64 (iterations summed over
        runs); pairs (n,) int64 refinement pairs of the kept run (0 without); run_angles
        (n, R, n_state) and run_error (n, R) every run's result and E (NaN for runs not
        made; R >= max_runs), the candidate postures of :mod:`kinematics.fit.temporal`. At least
        ``min_runs`` runs are made on frames with observations.
    """
    # Unpacked once here; the loops below pass plain arrays (a tuple passed to a
    # non-inlined call costs reference counting on every call).
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = body
    kind, P, K, dist, R, t = cams
    free_idx, step, hist, nbins, dof_kind, lo, hi = dofs
    (th, max_redraws, n_end, n_l, n_tau, tau0, l0, c_l, c_tau, eps, seed,
     reanalysis_threshold, max_runs, _, _, start_previous, max_unexplained, min_runs) = schedule
    claim_gate = parts[4]
    partitioned = parts[0].shape[0] > 1 or parts[5] > 0
    confirm = parts[11]
    bidirectional, weight, cap, penalty_cap, one = error
    objective, det_points, det_conf, det_off, obs3 = obs
    out_iterations, out_pairs, out_run_angles, out_run_error = out[4:]
    nv = kind.shape[0]
    nj = parent.shape[0]
    nm = marker_joint.shape[0]
    na = start.shape[0]
    for s in prange(seg_off.shape[0] - 1):
        rot = np.empty((nj, 3, 3))
        pos = np.empty((nj, 3))
        mk = np.empty((nm, 3))
        proj = np.empty((nv, nm, 2))
        cs = np.empty(na)
        sn = np.empty(na)
        per_view = np.empty(nv)
        nearest = np.empty(nm, np.int64)
        claimed = np.zeros(max(det_points.shape[0], obs3.shape[1]), np.bool_)
        d2 = np.empty(nm + obs3.shape[1] if objective == OBJ_CLOUD else 0)
        work = np.empty(na)
        cur = np.empty(na)
        cand = np.empty(na)
        best = np.empty(na)
        keep = np.empty(na)
        keep_mk = np.empty((nm, 3))
        annealed = np.empty(na)
        first = start.copy()
        for f in range(seg_off[s], seg_off[s + 1]):
            vo = det_off[f * nv: f * nv + nv + 1]
            rp = root_pos[f]
            rr = root_rot[f]
            clear_frame(out, f)
            if observed(objective, vo, obs3[f]):  # else nothing to fit
                e_keep = np.inf
                run = 0
                u_keep = 1 << 30  # with max_unexplained < 0 only E decides (u stays 0)
                confirmed = confirm <= 0.0
                while wants_run(run, min_runs, max_runs, e_keep, u_keep, reanalysis_threshold,
                                max_unexplained) or (run < max_runs and not confirmed):
                    state = stream_state(seed, frame_ids[f], run)
                    origin = first if run == 0 else start
                    if partitioned:
                        e, its = anneal_partitions(origin, state, rp, rr, body, cams, dofs,
                                                   schedule, error, objective, det_points,
                                                   det_conf, vo, obs3[f], parts, claimed,
                                                   work, cur, cand, best, cs, sn, rot, pos,
                                                   mk, proj, per_view, nearest)
                    else:
                        e, its = anneal_chain(origin, free_idx, step, hist, nbins, th,
                                              dof_kind, lo, hi, max_redraws, n_end, n_l,
                                              n_tau, tau0, l0, c_l, c_tau, eps, state, rp, rr,
                                              parent, chain, pre_rot, pre_trans, post_trans,
                                              elem_axis, elem_index, joint_flags,
                                              marker_joint, marker_local, slide_index, kind,
                                              P, K, dist, R, t, objective, det_points,
                                              det_conf, vo, obs3[f], bidirectional, weight,
                                              cap, penalty_cap, one, 0, nj, 0, nm, claimed, cur,
                                              cand, best, cs, sn, rot, pos, mk, proj,
                                              per_view, nearest, d2)
                    out_iterations[f] += its
                    e, pairs, u = finish_run(best, e, rp, rr, body, cams, dofs, schedule,
                                             error, objective, det_points, det_conf, vo,
                                             obs3[f], claim_gate, annealed, cs, sn, rot, pos,
                                             mk, proj, per_view, nearest)
                    out_run_angles[f, run, :] = best
                    out_run_error[f, run] = e
                    better = keeps(e, u, e_keep, u_keep, max_unexplained)
                    if confirm > 0.0:
                        project_posture(best, rp, rr, parent, chain, pre_rot, pre_trans,
                                        post_trans, elem_axis, elem_index, joint_flags,
                                        marker_joint, marker_local, slide_index, kind, P, K,
                                        dist, R, t, cs, sn, rot, pos, mk, proj)
                        if run > 0 and same_markers(mk, keep_mk, confirm):
                            confirmed = True  # the best run and this one agree
                        elif better:
                            confirmed = False  # a new best, found once
                        if better:
                            keep_mk[:] = mk
                    if better:
                        e_keep = e
                        u_keep = u
                        keep[:] = best
                        out_pairs[f] = pairs
                    run += 1
                write_frame(out, f, keep, run, rp, rr, body, cams, error, objective,
                            det_points, det_conf, vo, obs3[f], cs, sn, rot, pos, mk, proj,
                            per_view, nearest)
                if start_previous:
                    first[:] = keep


@njit(cache=True, nogil=True)
def solve_spd(a, b, n):
    """Solve ``a[:n, :n] · x = b[:n]`` for symmetric positive semi-definite ``a`` in place
    (Cholesky without pivoting; ``a`` is overwritten by its factor, ``b`` by x). A
    non-positive pivot zeroes that unknown (a direction the data do not constrain)."""
    for j in range(n):
        d = a[j, j]
        for k in range(j):
            d -= a[j, k] * a[j, k]
        ok = d > 1e-300
        d = math.sqrt(d) if ok else 0.0
        a[j, j] = d
        for i in range(j + 1, n):
            s = a[i, j]
            for k in range(j):
                s -= a[i, k] * a[j, k]
            a[i, j] = s / d if ok else 0.0
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= a[i, k] * b[k]
        b[i] = s / a[i, i] if a[i, i] > 0.0 else 0.0
    for i in range(n - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, n):
            s -= a[k, i] * b[k]
        b[i] = s / a[i, i] if a[i, i] > 0.0 else 0.0


# -- root marker tracking (Sect. 2.1, 3.3.1) ---------------------------------------------
@njit(cache=True, nogil=True)
def track_root(det_points, det_off, x0, gate, ridge, cams, out):
    """Follow one root marker through frames by nearest neighbour in every view.

    For each frame in turn, the marker's previous 3D position is projected into every view;
    the nearest detection there (within ``gate`` pixels) is its observation; the new 3D
    position minimises the squared reprojection error over the observing views plus
    ``ridge`` times the squared distance to the previous position (so directions no view
    sees, e.g. depth in a single orthographic view, stay put). Gauss-Newton with numerical
    Jacobians: exact in one step for orthographic views, a few steps for pinhole ones. A
    frame where no view sees a detection keeps the previous position, and the gate doubles
    for every such frame until the marker is seen again (re-acquisition after a gap).

    Parameters
    ----------
    det_points : (n_points, 2); det_off : (n_frames * n_views + 1,) int64, frame-major.
    x0 : (3,) the marker's position before the first frame; cams : CameraArrays.
    out : (n_frames, 3) tracked positions.

    Returns
    -------
    n_lost : int, frames where no view observed the marker.
    """
    kind, P, K, dist, R, t = cams
    nv = kind.shape[0]
    nf = out.shape[0]
    obs = np.empty((nv, 2))
    seen = np.zeros(nv, np.bool_)
    prev = x0.copy()
    x = x0.copy()
    a = np.empty((3, 3))
    g = np.empty(3)
    jv = np.empty((2, 3))
    n_lost = 0
    h = 1e-6 * (1.0 + np.abs(x0).max())
    search = gate
    for f in range(nf):
        n_seen = 0
        for v in range(nv):
            pu, pv = project_point(kind, P, K, dist, R, t, v, prev[0], prev[1], prev[2])
            lo = det_off[f * nv + v]
            hi = det_off[f * nv + v + 1]
            best = search * search
            arg = -1
            for c in range(lo, hi):
                dx = det_points[c, 0] - pu
                dy = det_points[c, 1] - pv
                d2 = dx * dx + dy * dy
                if d2 < best or (arg < 0 and d2 <= best):
                    best = d2
                    arg = c
            seen[v] = arg >= 0
            if arg >= 0:
                obs[v, 0] = det_points[arg, 0]
                obs[v, 1] = det_points[arg, 1]
                n_seen += 1
        if n_seen == 0:
            n_lost += 1
            search *= 2.0  # re-acquisition: the marker may have moved on during the gap
        else:
            search = gate
            for k in range(3):
                x[k] = prev[k]
            for _ in range(8):
                for r in range(3):
                    g[r] = ridge * (prev[r] - x[r])
                    for c in range(3):
                        a[r, c] = ridge if r == c else 0.0
                for v in range(nv):
                    if seen[v]:
                        u0, w0 = project_point(kind, P, K, dist, R, t, v, x[0], x[1], x[2])
                        for k in range(3):
                            x[k] += h
                            u1, w1 = project_point(kind, P, K, dist, R, t, v, x[0], x[1], x[2])
                            x[k] -= h
                            jv[0, k] = (u1 - u0) / h
                            jv[1, k] = (w1 - w0) / h
                        ru = obs[v, 0] - u0
                        rv = obs[v, 1] - w0
                        for r in range(3):
                            g[r] += jv[0, r] * ru + jv[1, r] * rv
                            for c in range(3):
                                a[r, c] += jv[0, r] * jv[0, c] + jv[1, r] * jv[1, c]
                solve_spd(a, g, 3)
                for k in range(3):
                    x[k] += g[k]
            for k in range(3):
                prev[k] = x[k]
        for k in range(3):
            out[f, k] = prev[k]
    return n_lost


# Refinement runs inside the re-analysis loop of fit_frames, but its kernels build on this
# module; importing the module object (not names) last keeps the import cycle harmless in
# either import order (numba resolves _rk.refine_posture when fit_frames compiles).
from kinematics._kernels import refine as _rk  # noqa: E402
