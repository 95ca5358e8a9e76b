"""The whole fitter runs with numba's JIT off (every kernel as plain Python over NumPy
arrays): the kernels are their own reference implementation, and a failure there shows up
as a Python traceback instead of a compiled crash."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

from tests.fixtures.paths import BIND_TESTS_PACKAGE, REPO

SCRIPT = BIND_TESTS_PACKAGE + r"""
import json, numpy as np
from kinematics.fit import AnnealParams, Fitter
from kinematics.observe.observations import Observations
from tests.fixtures.bodies import mouse_like
from tests.fixtures.cameras import three_pinholes
from tests.fixtures.planted import planted_frames
body, cams = mouse_like(), three_pinholes()
angles, roots, frames = planted_frames(body, cams, n=2)
params = AnnealParams.paper(refine=True, max_runs=1, seed=3).with_schedule(300)
out = {}
res = Fitter(body, cams, params).fit(frames)
out["blobs"] = [[*r.angles_deg, *r.root_positions.ravel(), r.error] for r in res]
kp = Observations.keypoints(np.array(frames), [c.name for c in cams], body.marker_names,
                            body.marker_names)
res = Fitter(body, cams, params).fit(kp)
out["keypoints"] = [[*r.angles_deg, *r.root_positions.ravel(), r.error] for r in res]
print(json.dumps(out))
"""


def run(jit_off: bool) -> dict:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    if jit_off:
        env["NUMBA_DISABLE_JIT"] = "1"
    proc = subprocess.run([sys.executable, "-c", SCRIPT], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_fitter_runs_with_jit_off_and_agrees():
    off, on = run(True), run(False)
    for kind in ("blobs", "keypoints"):
        np.testing.assert_allclose(off[kind], on[kind], rtol=1e-6, atol=1e-6)
