"""The whole fitter runs with numba's JIT off (every kernel as plain Python over NumPy
arrays): the kernels are their own reference implementation, and a failure there shows up
as a Python traceback instead of a compiled crash."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]

SCRIPT = r"""
import json, numpy as np
from kinematics.anneal import AnnealParams, Fitter
from kinematics.observations import Observations
import sys
sys.path.insert(0, "tests/kinematics")  # by path: a package may install its own 'tests'
from test_free_root import mouse_like, planted_frames, three_pinholes
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
