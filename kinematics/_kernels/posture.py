"""A posture's markers in 3D and in every view: forward kinematics over the folded body
layout (:func:`kinematics.fit.problem.fold_body`) and the camera models of
:mod:`kinematics._kernels.camera`. Twin: :func:`kinematics.model.fk.forward_kinematics_reference`
with :meth:`kinematics.cameras.Camera.project`."""

from __future__ import annotations

from numba import njit

from kinematics._kernels.camera import ORTHOGRAPHIC, project_point
from kinematics._kernels.codes import G_IDENTITY, H_ZERO, OBJ_CLOUD, OBJ_POINTS3D, ROOT_POSE
from kinematics._kernels.fastmath import sincos


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
def project_cs(values, cs, sn, root_pos, root_rot, body, cams, views, rot, pos, mk, proj,
               any_pinhole, span, marks):
    """Markers of the posture with cosines ``cs`` and sines ``sn`` (n_axes,) of the folded
    ``body`` projected into the first ``views.shape[0]`` cameras of ``cams`` (``views``:
    ``cams.kind`` or a slice of it; :func:`drawn_views`): fills ``proj`` (n_views,
    n_markers, 2); ``rot`` (nj, 3, 3), ``pos`` (nj, 3) and ``mk`` (nm, 3) receive A'_j, the
    joint centres and the 3D markers. ``any_pinhole`` says whether ``views`` has a pinhole
    view. A marker hidden in a pinhole
    view by ``marks`` (a frame's hidden marks, :func:`hidden_in`; an empty array for none)
    is not projected there: every reader skips it, and with one view per camera and marker
    colour most markers are hidden in most views. ``span = (j0, j1, m0, m1)``:
    only joints ``j0:j1`` and markers ``m0:m1`` are computed (a partition's subtree; its
    parents' ``rot``, ``pos`` must be current); ``(0, nj, 0, nm)`` computes everything.

    For calls outside a loop: a field taken from a record costs reference counting, so the
    loops unpack the records once and call :func:`posture_frames` and
    :func:`posture_markers` with plain arrays."""
    j0, j1, m0, m1 = span
    posture_frames(values, cs, sn, root_pos, root_rot, body.parent, body.chain, body.pre_rot,
                   body.pre_trans, body.post_trans, body.elem_axis, body.elem_index,
                   body.joint_flags, body.slide_index, rot, pos, j0, j1)
    posture_markers(body.marker_joint, body.marker_local, rot, pos, mk, proj, views, cams.P,
                    cams.K, cams.dist, cams.R, cams.t, any_pinhole, m0, m1, marks)


@njit(cache=True, nogil=True, inline="always")
def posture_frames(values, cs, sn, root_pos, root_rot, parent, chain, pre_rot, pre_trans,
                   post_trans, elem_axis, elem_index, joint_flags, slide_index, rot, pos, j0,
                   j1):
    """The joint frames ``rot`` (nj, 3, 3) A'_j and centres ``pos`` (nj, 3) of joints
    ``j0:j1`` (Eq. 1, 2) of the posture with cosines ``cs`` and sines ``sn``; the
    parents of ``j0`` must be current. The first half of :func:`project_cs`."""
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


@njit(cache=True, nogil=True, inline="always")
def posture_markers(marker_joint, marker_local, rot, pos, mk, proj, views, P, K, dist, R, t,
                    any_pinhole, m0, m1, marks):
    """The 3D markers ``mk[m0:m1]`` on their joints' frames and their projections into
    ``views`` (``proj``), not where ``marks`` hides them in a pinhole view. The second half
    of :func:`project_cs`."""
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
        for v in range(views.shape[0]):
            proj[v, m, 0] = P[v, 0, 0] * x + P[v, 0, 1] * y + P[v, 0, 2] * z + P[v, 0, 3]
            proj[v, m, 1] = P[v, 1, 0] * x + P[v, 1, 1] * y + P[v, 1, 2] * z + P[v, 1, 3]
    if any_pinhole:
        project_pinhole(views, P, K, dist, R, t, mk, proj, m0, m1, marks)


@njit(cache=True, nogil=True)
def project_pinhole(kind, P, K, dist, R, t, mk, proj, m0, m1, marks):
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
def has_pinhole(kind):
    out = False
    for v in range(kind.shape[0]):
        out = out or kind[v] != ORTHOGRAPHIC
    return out


@njit(cache=True, nogil=True, inline="always")
def drawn_views(kind, objective):
    """The views a search projects its draws into (``kind``, sliced): none where the
    objective is 3D (points or a cloud), which reads only the 3D markers."""
    return kind[:0] if objective in (OBJ_POINTS3D, OBJ_CLOUD) else kind[:]


@njit(cache=True, nogil=True)
def project_posture(angles, root_pos, root_rot, body, cams, cs, sn, rot, pos, mk, proj):
    """Forward kinematics (Eq. 1, 2) and projection (Eq. 3) of every marker of posture
    ``angles`` (n_axes,) radians of the folded ``body`` into every view of ``cams``
    (as many as ``proj`` has): fills ``proj`` (n_views, n_markers, 2);
    ``cs``, ``sn`` (n_axes,), ``rot`` (nj, 3, 3), ``pos`` (nj, 3), ``mk`` (nm, 3) are
    scratch (holding the joint centres and 3D markers afterwards)."""
    for k in range(angles.shape[0]):
        sn[k], cs[k] = sincos(angles[k])
    views = cams.kind[:proj.shape[0]]
    project_cs(angles, cs, sn, root_pos, root_rot, body, cams, views, rot, pos, mk, proj,
               has_pinhole(views), (0, body.parent.shape[0], 0, body.marker_joint.shape[0]),
               mk[:0])


@njit(cache=True, nogil=True, inline="always")
def hidden_in(obs3, i, v):
    """Whether unlabelled 2D points skip model marker ``i`` in view ``v`` because the user
    marked it hidden there (occluded, or its blob merged with another). For unlabelled
    points a frame's ``obs3`` holds these marks, shape (n_markers, n_views), nonzero =
    hidden; an array of any other shape (e.g. (0, 4)) hides nothing. A hidden marker costs
    nothing in that view, takes no detection and explains none."""
    return i < obs3.shape[0] and v < obs3.shape[1] and obs3[i, v] != 0.0
