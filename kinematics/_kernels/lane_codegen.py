"""Lane kernels generated for one body and its views (private; used by
:mod:`kinematics._kernels.lanes` through ``Fitter``'s lane backend).

The general lane kernel walks joints, markers, views and detections in loops over arrays,
with a loop over the lanes innermost: every stage stores its results for all lanes (A'_j,
joint centres, marker images) and the next stage loads them back. Generated code instead
computes one lane's whole E in straight-line code — sines and cosines, forward kinematics,
projection and Eq. 5 with its variants — inside a single loop over the lanes, so every
intermediate value stays in a vector register and the only stores are the lanes' E.

The body's and cameras' constants are written into the source as literals, and a product
with a literal 0 or 1 is left out (folded joints have many: identity rotations, offsets
along one axis, orthographic views that drop a coordinate). Leaving out ``x · 0`` and
``x + 0`` changes nothing for finite values but the sign of a zero, so E and the angles
are the scalar kernel's to the last bit (tests/kinematics/test_lane_codegen.py) wherever the
postures and roots are finite (a NaN root makes every marker NaN in both). The float32
variant (``single``, precision "float32") is the exception: the same code in float32, within
float32 rounding of the scalar kernel's E.

The number of detections per view is a constant of the generated code too (the lanes'
detections padded with :data:`kinematics._kernels.lanes.PAD`), so the scan over them is
unrolled; :func:`fused_kernel` generates a kernel per padded count and caches it, in memory
and as a source file beside numba's cache, where numba caches its machine code.
"""

from __future__ import annotations

import hashlib
import importlib.util
import sys
import threading
from pathlib import Path

import numpy as np
from numba.core import config

from kinematics._kernels.cache import default_cache_dir
from kinematics._kernels.camera import ORTHOGRAPHIC
from kinematics._kernels.codes import G_IDENTITY, H_ZERO, NAN_MARKER_COST, ROOT_POSE
from kinematics.fileio import atomic_write_text


def _kernels_digest() -> str:
    """A digest of the kernels a generated module imports (and numba inlines into it):
    numba's cache keys a module by its own file only, so this goes into every generated
    file, and an upgrade that changes them makes new files instead of reusing stale
    machine code."""
    try:
        return hashlib.sha256(b"".join(
            (Path(__file__).parent / name).read_bytes()
            for name in ("codes.py", "fastmath.py", "camera.py", "lanes.py", "lane_codegen.py")
        )).hexdigest()[:16]
    except OSError:  # sources not shipped (a frozen app): numba cannot cache them either
        return "unknown"


_INLINED = _kernels_digest()

#: Generated code is only worth its compile time (and stays of a size LLVM handles) up to
#: this many marker images (markers × views).
MAX_IMAGES = 256

#: ... and up to this many detections in a view: beyond, LLVM no longer unrolls the scans
#: over them (:data:`SCAN_CHUNK`), and a loop inside the loop over lanes keeps that loop
#: scalar (the locust, one thread, ns per iteration generated / general: 16 detections
#: 64 / 102, 20: 66 / 112, 24: 72 / 121, 28: 79 / 129, 32: 376 / 138; in one loop of 20
#: detections, as before the chunks: 270 / 113).
MAX_DETECTIONS = 28

_lock = threading.Lock()
_loaded: dict[str, object] = {}


class _Code:
    """Straight-line source with literals folded: a value is a float (a literal) or the
    name of a local variable. ``single``: the code computes in float32; its literals are
    float32 constants named before the loop (a bare literal is a float64 in numba, and one
    would turn every value it touches into float64), and folding rounds to float32."""

    def __init__(self, single: bool = False):
        self.lines: list[str] = []
        self.n = 0
        self.single = single
        self.real = np.float32 if single else np.float64
        self.consts: dict[str, str] = {}  # float32 mode: a literal's text -> its name

    def constants(self) -> list[str]:
        """The float32 constants' definitions (before the loop over lanes)."""
        return [f"{name} = np.float32({text})" for text, name in self.consts.items()]

    def load(self, expr: str) -> str:
        """A float64 array element as a value of the code's precision."""
        return self.let(f"np.float32({expr})" if self.single else expr)

    def let(self, expr: str) -> str:
        self.n += 1
        name = f"t{self.n}"
        self.lines.append(f"{name} = {expr}")
        return name

    def lit(self, x: float, nan: bool = False) -> str:
        """The literal ``x`` (``nan``: NaN, which is never folded)."""
        if np.isnan(x) and not nan:
            raise ValueError("a NaN constant cannot be folded into generated code")
        text = ("np.nan" if np.isnan(x) else repr(float(x)) if np.isfinite(x)
                else "np.inf" if x > 0 else "-np.inf")
        if not self.single:
            return text
        return self.consts.setdefault(text, f"k{len(self.consts)}")

    def term(self, a) -> str:
        return self.lit(a) if isinstance(a, float) else a

    def mul(self, a, b):
        if isinstance(a, float) and isinstance(b, float):
            return float(self.real(a) * self.real(b))
        if a == 0.0 or b == 0.0:
            return 0.0
        if a == 1.0:
            return b
        if b == 1.0:
            return a
        if a == -1.0:
            return self.neg(b)
        if b == -1.0:
            return self.neg(a)
        return self.let(f"{self.term(a)} * {self.term(b)}")

    def neg(self, a):
        return -a if isinstance(a, float) else self.let(f"-{a}")

    def add(self, a, b):
        if isinstance(a, float) and isinstance(b, float):
            return float(self.real(a) + self.real(b))
        if b == 0.0:
            return a
        if a == 0.0:
            return b
        return self.let(f"{self.term(a)} + {self.term(b)}")

    def sub(self, a, b):
        if isinstance(a, float) and isinstance(b, float):
            return float(self.real(a) - self.real(b))
        if b == 0.0:
            return a
        if a == 0.0:
            return self.neg(b)
        return self.let(f"{self.term(a)} - {self.term(b)}")

    def div(self, a, b):
        if isinstance(a, float) and isinstance(b, float):
            return float(self.real(a) / self.real(b))
        if b == 1.0:
            return a
        return self.let(f"{self.term(a)} / {self.term(b)}")

    def dot(self, terms, start=None):
        """``start + a0·b0 + a1·b1 + ...`` summed left to right, as the scalar kernel."""
        acc = start
        for a, b in terms:
            t = self.mul(a, b)
            acc = t if acc is None else self.add(acc, t)
        return acc


def _mul33(code: _Code, q, m):
    return [code.dot([(q[3 * r], m[c]), (q[3 * r + 1], m[3 + c]), (q[3 * r + 2], m[6 + c])])
            for r in range(3) for c in range(3)]


# the two columns a rotation about world axis x, y, z mixes (the scalar kernel's order)
_MIXED = {0: (1, 2), 1: (2, 0), 2: (0, 1)}


def _kinematics(code: _Code, folded):
    """Joint frames and markers of one lane: the scalar ``project_cs``, folded."""
    (parent, chain, pre_rot, pre_trans, post_trans, elem_axis, elem_index, joint_flags,
     marker_joint, marker_local, slide_index) = folded
    nj = parent.shape[0]
    used = sorted({int(elem_index[j, e]) for j in range(nj) for e in range(3)
                   if elem_axis[j, e] >= 0})
    sin, cos = {}, {}
    for i in used:
        sin[i], cos[i] = f"s{i}", f"c{i}"
        code.lines.append(f"s{i}, c{i} = {'sincos32' if code.single else 'sincos'}"
                          f"(cand[{i}, ln])")
    rot, pos = [], []
    for j in range(nj):
        p = int(parent[j])
        m = [float(x) for x in pre_rot[j].ravel()]
        if p < 0:
            c = int(chain[j])
            px, py, pz = (code.load(f"pos[{nj + c}, {k}, ln]") for k in range(3))
            b = m
            if joint_flags[j] & ROOT_POSE:
                q = [code.load(f"rot[{nj + c}, {k}, ln]") for k in range(9)]
                b = _mul33(code, q, m)
                k = int(slide_index[j])
                px, py, pz = (code.add(v, code.load(f"cand[{k + d}, ln]"))
                              for d, v in enumerate((px, py, pz)))
        else:
            q = rot[p]
            g = [float(x) for x in pre_trans[j]]
            px, py, pz = (code.dot([(q[3 * r + k], g[k]) for k in range(3)], pos[p][r])
                          for r in range(3))
            b = list(q) if joint_flags[j] & G_IDENTITY else _mul33(code, q, m)
        for e in range(3):
            a = int(elem_axis[j, e])
            if a < 0:
                continue
            i = int(elem_index[j, e])
            u, w = _MIXED[a]
            for r in range(3):
                bu, bw = b[3 * r + u], b[3 * r + w]
                b[3 * r + u] = code.add(code.mul(cos[i], bu), code.mul(sin[i], bw))
                b[3 * r + w] = code.sub(code.mul(cos[i], bw), code.mul(sin[i], bu))
        if not joint_flags[j] & H_ZERO:
            h = [float(x) for x in post_trans[j]]
            # px += (b00·h0 + b01·h1 + b02·h2): the sum first, as the scalar kernel
            px, py, pz = (code.add(v, code.dot([(b[3 * r + k], h[k]) for k in range(3)]))
                          for r, v in enumerate((px, py, pz)))
        rot.append(b)
        pos.append((px, py, pz))
    markers = []
    for mi in range(marker_joint.shape[0]):
        j = int(marker_joint[mi])
        a = [float(x) for x in marker_local[mi]]
        markers.append([code.dot([(rot[j][3 * r + k], a[k]) for k in range(3)], pos[j][r])
                        for r in range(3)])
    return markers


def _project(code: _Code, cams, v: int, x):
    """Marker ``x`` in view ``v`` (``project_point``): (u, w), NaN behind a pinhole camera."""
    kind, P, K, dist, R, t = cams
    if kind[v] == ORTHOGRAPHIC:
        return tuple(code.dot([(float(P[v, r, k]), x[k]) for k in range(3)] +
                              [(float(P[v, r, 3]), 1.0)]) for r in range(2))
    xc, yc, zc = (code.dot([(float(R[v, r, k]), x[k]) for k in range(3)] +
                           [(float(t[v, r]), 1.0)]) for r in range(3))
    xn, yn = code.div(xc, zc), code.div(yc, zc)
    k1, k2, p1, p2, k3, k4, k5, k6 = (float(d) for d in dist[v])
    mul, add = code.mul, code.add
    r2 = add(mul(xn, xn), mul(yn, yn))
    num = add(1.0, mul(r2, add(k1, mul(r2, add(k2, mul(r2, k3))))))
    den = add(1.0, mul(r2, add(k4, mul(r2, add(k5, mul(r2, k6))))))
    radial = code.div(num, den)
    xd = add(add(mul(xn, radial), mul(mul(mul(2.0, p1), xn), yn)),
             mul(p2, add(r2, mul(mul(2.0, xn), xn))))
    yd = add(add(mul(yn, radial), mul(p1, add(r2, mul(mul(2.0, yn), yn)))),
             mul(mul(mul(2.0, p2), xn), yn))
    front = code.let(f"{code.term(zc)} > {code.lit(0.0)}")
    u = add(mul(float(K[v, 0, 0]), xd), float(K[v, 0, 2]))
    w = add(mul(float(K[v, 1, 1]), yd), float(K[v, 1, 2]))
    nan = code.lit(np.nan, nan=True)
    return (code.let(f"{code.term(u)} if {front} else {nan}"),
            code.let(f"{code.term(w)} if {front} else {nan}"))


#: The scan over a view's detections is written as loops of at most this many detections:
#: LLVM unrolls a loop of a constant count up to about 16, and keeps a longer one a loop,
#: which keeps the loop over lanes around it scalar. (Chunks of 8 did worse: 24 detections
#: as three loops of 8 stayed scalar, 273 ns, as 16 + 8 not, 72 ns; why, not found.)
SCAN_CHUNK = 16


def _scans(n_det: int) -> list[tuple[int, int]]:
    """[first, end) of each loop scanning ``n_det`` detections, in order."""
    return [(c, min(c + SCAN_CHUNK, n_det)) for c in range(0, n_det, SCAN_CHUNK)]


def _error(code: _Code, images, n_det: int, error) -> str:
    """E of one lane (the scalar ``projection_error`` without one-to-one and hidden marks)
    from ``images[v][m]``, the marker images, against ``n_det`` detections per view (the
    lane's own, then padding). The scans over detections are loops of a constant count in
    the source, which LLVM unrolls: written out, the source of a few thousand lines took
    numba 8-120 s to compile."""
    bidirectional, weight, cap, penalty_cap = error
    lit = code.lit
    zero, inf = lit(0.0), lit(np.inf)
    missing = lit(cap if cap < np.inf else NAN_MARKER_COST)
    # float32: the detections' float32 copies and an int32 index, so every value of the
    # loop has 32 bits and a vector holds 16 lanes
    dx, dy = ("dx32", "dy32") if code.single else ("dx", "dy")
    none, this = ("np.int32(-1)", "np.int32(c)") if code.single else ("-1", "c")
    out = code.lines
    total = zero
    for v, view in enumerate(images):
        ev = f"ev{v}"
        out.append(f"{ev} = {zero}")
        for m, (pu, pw) in enumerate(view):
            b, a = f"b{v}_{m}", f"a{v}_{m}"
            out += [f"{b} = {inf}", f"{a} = {none}"]
            for first, end in _scans(n_det):
                out += [f"for c in range({first}, {end}):",
                        f"    ex = {code.term(pu)} - {dx}[{v}, c, ln]",
                        f"    ey = {code.term(pw)} - {dy}[{v}, c, ln]",
                        "    d2 = ex * ex + ey * ey",
                        f"    closer = d2 < {b}",
                        f"    {b} = d2 if closer else {b}",
                        f"    {a} = {this} if closer else {a}"]
            out += [f"d = np.sqrt({b}) if {a} >= 0 else {missing}",
                    f"{ev} = {ev} + min(d, {lit(cap)})"]
        if bidirectional:
            matched = " | ".join(f"({f'a{v}_{m}'} == c)" for m in range(len(view)))
            for first, end in _scans(n_det):
                out += [f"for c in range({first}, {end}):", f"    near = {inf}"]
                for pu, pw in view:
                    out += [f"    ex = {code.term(pu)} - {dx}[{v}, c, ln]",
                            f"    ey = {code.term(pw)} - {dy}[{v}, c, ln]",
                            "    near = min(near, ex * ex + ey * ey)"]
                out += [f"    add = (not ({matched})) & (c < ndet[{v}, ln])",
                        f"    d = np.sqrt(near) if near < {inf} else {missing}",
                        f"    {ev} = {ev} + {lit(weight)} * min(d, {lit(penalty_cap)}) "
                        f"if add else {ev}"]
        total = code.let(f"{total} + ({ev} if ndet[{v}, ln] > 0 else {zero})")
    return total


def _labelled_error(code: _Code, images, cap) -> str:
    """Labelled E of one lane (the scalar ``labelled_error``, same operations in the same
    order): marker image ``images[v][m]`` against keypoint m of view v, ``dx, dy [v, m]``
    of weight ``dw [v, m]``, where the view holds the markers' rows (``ndet``)."""
    lit = code.lit
    missing = lit(cap if cap < np.inf else NAN_MARKER_COST)
    out = code.lines
    total = lit(0.0)
    for v, view in enumerate(images):
        ev = f"ev{v}"
        out.append(f"{ev} = {lit(0.0)}")
        out.append(f"full = ndet[{v}, ln] == {len(view)}")
        for m, (pu, pw) in enumerate(view):
            out += [f"w = dw[{v}, {m}, ln]",
                    f"kx = dx[{v}, {m}, ln]",
                    f"ky = dy[{v}, {m}, ln]",
                    f"ex = {code.term(pu)} - kx",
                    f"ey = {code.term(pw)} - ky",
                    "d = np.sqrt(ex * ex + ey * ey)",
                    f"add = w * min(d if np.isfinite(d) else {missing}, {lit(cap)})",
                    "use = full & (w > 0.0) & np.isfinite(kx) & np.isfinite(ky)",
                    f"{ev} = {ev} + (add if use else {lit(0.0)})"]
        total = code.let(f"{total} + {ev}")
    return total


def _points3d_error(code: _Code, markers, cap) -> str:
    """3D-point E of one lane (the scalar ``points3d_error``, same operations in the same
    order): marker ``markers[m]`` against its own point ``o3[m, :3]`` of weight
    ``o3[m, 3]``."""
    lit = code.lit
    out = code.lines
    total = lit(0.0)
    for m, (x, y, z) in enumerate(markers):
        out += [f"w = o3[{m}, 3, ln]",
                f"ox = o3[{m}, 0, ln]",
                f"oy = o3[{m}, 1, ln]",
                f"oz = o3[{m}, 2, ln]",
                f"ex = {code.term(x)} - ox",
                f"ey = {code.term(y)} - oy",
                f"ez = {code.term(z)} - oz",
                f"add = w * min(np.sqrt(ex * ex + ey * ey + ez * ez), {lit(cap)})",
                "use = (w > 0.0) & np.isfinite(ox) & np.isfinite(oy) & np.isfinite(oz)"]
        total = code.let(f"{total} + (add if use else {lit(0.0)})")
    return total


def fused_source(folded, cams, n_det: int, error, single: bool = False,
                 labelled: bool = False, points3d: bool = False) -> str:
    """Source of a module whose ``evaluate`` (a numba ``cfunc`` of
    :data:`kinematics._kernels.lanes.FUSED_SIGNATURE`) writes every lane's E of the
    candidates ``cand`` into ``e``, against ``n_det`` detections per view.
    ``error``: (bidirectional, weight, cap, penalty_cap). ``single``: computed in float32
    from the detections' float32 copies ``dx32``, ``dy32`` (precision "float32"; E is
    then within float32 rounding of the scalar kernel's, not equal to it). ``labelled``:
    E of labelled 2D keypoints instead (the detections are the markers' keypoints, of
    weights ``dw``; float64 only); ``points3d``: E of labelled 3D points ``o3`` (float64
    only)."""
    if (labelled or points3d) and single:
        raise ValueError("labelled keypoints and 3D points have no float32 kernel")
    code = _Code(single)
    markers = _kinematics(code, folded)
    images = [[_project(code, cams, v, x) for x in markers] for v in range(len(cams[0]))]
    if points3d:
        total = _points3d_error(code, markers, error[2])
    elif labelled:
        total = _labelled_error(code, images, error[2])
    else:
        total = _error(code, images, n_det, tuple(error))
    consts = "".join("    " + line + "\n" for line in code.constants())
    body = "\n".join("        " + line for line in code.lines)
    precision = "float32" if single else "float64"
    against = ("its markers' 3D points" if points3d else "its markers' keypoints" if labelled
               else f"{n_det} detections per view")
    return f'''"""Generated by kinematics._kernels.lane_codegen for one body, its views and
{against}, in {precision}: every lane's E in one loop (do not edit; kernels
{_INLINED})."""
import numpy as np
from numba import cfunc

from kinematics._kernels.fastmath import sincos, sincos32
from kinematics._kernels.lanes import FUSED_SIGNATURE


@cfunc(FUSED_SIGNATURE, cache=True, nopython=True, error_model="numpy")
def evaluate(cand, rot, pos, dx, dy, dx32, dy32, dw, o3, ndet, e):
{consts}    for ln in range(e.shape[0]):
{body}
        e[ln] = {total}
'''


def padded_detections(c_cap: int) -> int:
    """Detections per view a kernel scans for a block with at most ``c_cap``: the count
    itself up to 8, then rounded up to a multiple of 4, so blocks share kernels."""
    return max(1, c_cap) if c_cap <= 8 else -(-c_cap // 4) * 4


def fits(folded, cams, c_cap: int, points3d: bool = False) -> bool:
    """Whether a generated kernel is worth making for this body, views and detections (3D
    points: for this body)."""
    images = folded.marker_joint.shape[0] * (1 if points3d else len(cams.kind))
    return 0 < images <= MAX_IMAGES and c_cap <= MAX_DETECTIONS


def generated_dir() -> Path:
    """Where generated sources are kept: beside numba's cache (:mod:`kinematics._kernels.cache`
    sets its folder before any kernel compiles)."""
    return Path(config.CACHE_DIR or default_cache_dir()) / "lanes"


def source_path(src: str) -> Path:
    """Where generated source ``src`` is kept: named by its hash."""
    return generated_dir() / f"lanes_{hashlib.sha256(src.encode()).hexdigest()[:20]}.py"


def fused_kernel(folded, cams, c_cap: int, error, single: bool = False,
                 labelled: bool = False, points3d: bool = False):
    """The generated ``evaluate`` cfunc for this body, views, detections, error, precision
    and objective (``labelled``: 2D keypoints; ``points3d``: 3D points), made (and compiled)
    on first use; the source is kept in :func:`generated_dir`, named by its hash, so numba's
    cache of the machine code outlives the process."""
    src = fused_source(folded, cams, padded_detections(c_cap), error, single, labelled,
                       points3d)
    path = source_path(src)
    key = path.stem
    with _lock:
        if key in _loaded:
            return _loaded[key]
        path.parent.mkdir(parents=True, exist_ok=True)
        if not path.exists() or path.read_text(encoding="utf-8") != src:
            atomic_write_text(path, src)  # other processes see the whole file or none
        name = f"_videotrack_{key}"
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module  # numba's cache finds the module by this name
        spec.loader.exec_module(module)
        _loaded[key] = module.evaluate
        return module.evaluate
