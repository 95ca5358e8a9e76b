"""Scalar maths of the kernels, written so that results do not depend on the thread or the
SIMD lane: the counter-based random stream (splitmix64 per seed, frame and run), sine and
cosine, the logarithm of a uniform, and a small symmetric solve."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# -- random numbers: splitmix64 (Steele, Lea & Flood 2014) --------------------------------
GOLDEN = np.uint64(0x9E3779B97F4A7C15)
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
    s = mix64(np.uint64(seed) + GOLDEN)
    s = mix64(s ^ (np.uint64(frame) * _FRAME_KEY))
    return mix64(s ^ (np.uint64(run) * _RUN_KEY + GOLDEN))


@njit(cache=True, nogil=True, inline="always")
def next_uniform(state):
    """Advance the stream; returns ``(state, u)`` with ``u`` uniform in [0, 1) (53 bits)."""
    state = state + GOLDEN
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
