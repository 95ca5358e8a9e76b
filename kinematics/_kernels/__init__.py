"""The numba kernels (private): module-level ``@njit`` functions over arrays, no classes, no
I/O. Each has a readable NumPy twin in the public modules. :mod:`.cache` sets numba's
cache folder and must run before any kernel is decorated, so it is imported first.

Modules, lowest first (each imports only those above it):

* :mod:`.codes` — joint flags, state-entry kinds, objectives, empty "no claims" arrays;
  :mod:`.fastmath` — the random stream, sine/cosine, log, a small solve;
  :mod:`.camera` — the camera models.
* :mod:`.posture` — forward kinematics of the folded body and projection into the views.
* :mod:`.error2d`, :mod:`.error3d` — E against 2D detections and against 3D points;
  :mod:`.objective` — E by objective, for the whole body or one partition.
* :mod:`.refine` — Gauss-Newton refinement of a posture; :mod:`.anneal` — the annealing
  loop of Eq. 6, the start search and partitions; :mod:`.frames` — the per-frame procedure
  over many frames (the entry point of the scalar backend).
* :mod:`.lanes` (and the code it generates, :mod:`.lane_codegen`) and :mod:`.cuda` — the
  same procedure over SIMD lanes and GPU threads; :mod:`.root_track`, :mod:`.fk`,
  :mod:`.temporal`, :mod:`.triangulation` — kernels of their own jobs.

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
  sweep along x (:func:`.error2d.nearest_sorted`). For many frames ``det_off`` (n_frames * n_views +
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


from kinematics._kernels import cache  # noqa: F401  (numba's cache folder, before any kernel)
