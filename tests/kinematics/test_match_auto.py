"""``match = "auto"`` decides on the data: a single chain whose views hold many more
detections than it has markers (other limbs' markers) is matched in 3D, a chain seen alone
in its views is matched per view, and a frame of the fit is scored as the fit scored it."""

from __future__ import annotations

import numpy as np
import pytest

from kinematics.anneal import CLUTTER_RATIO, AnnealParams, Fitter
from kinematics.fk import forward_kinematics_reference
from kinematics.model import Body, Chain, Root
from kinematics.observations import Observations
from kinematics.settings import ErrorOptions
from tests.kinematics.test_cloud_objective import ring
from tests.kinematics.test_partitions import leg, planted

LEGS = (("a", (4.0, 0.0, 6.0), 45.0), ("b", (0.0, 0.0, 8.0), 90.0),
        ("c", (-4.0, 0.0, 6.0), 135.0))


def legs(names=("a", "b", "c")) -> Body:
    """Three two-marker legs side by side, each its own chain (or the ones named)."""
    return Body("legs", tuple(Chain(n, leg(n, at, yaw), Root("fixed"))
                              for n, at, yaw in LEGS if n in names), "px")


def with_extra(frames, k, seed=0):
    """Each view of each frame with ``k`` more detections, scattered over the image."""
    rng = np.random.default_rng(seed)
    return [[np.vstack([v, rng.uniform((0, 0), (640, 480), (k, 2))]) for v in f]
            for f in frames]


def test_auto_matches_a_chain_in_3d_where_its_views_hold_other_limbs_markers():
    cams = ring()
    one = Fitter(legs(("a",)), cams)
    _, among = planted(legs(), cams, 4, seed=1, shuffle=True)  # 6 markers drawn, 2 fitted
    _, alone = planted(legs(("a",)), cams, 4, seed=1, shuffle=True)
    assert one.match_for(among) == "3d" and one.observations(among).kind == "cloud"
    assert one.match_for(alone) == "views" and one.observations(alone).kind == "points"
    # the bound: detections per marker image, median over the frames
    assert one.match_for(with_extra(alone, int(2 * (CLUTTER_RATIO - 1)) - 1)) == "views"
    assert one.match_for(with_extra(alone, int(2 * (CLUTTER_RATIO - 1)) + 1)) == "3d"
    # 3D needs 3 views; a setting overrides; labelled data are not matched
    two = Fitter(legs(("a",)), dict(list(cams.items())[:2]))
    assert two.match_for([f[:2] for f in among]) == "views"
    views = Fitter(legs(("a",)), cams, AnnealParams(match="views"))
    assert views.match_for(among) == "views"
    pts = Observations.points_3d(np.zeros((1, 2, 3)), ["a_knee_mk", "a_tip"],
                                 ["a_knee_mk", "a_tip"])
    assert one.match_for(pts) == "3d"
    # several limbs are matched in 3D whatever the clutter
    assert Fitter(legs(), cams).match_for(among) == "3d"


def test_a_leg_among_others_fitted_with_the_defaults_and_scored_alike():
    """One leg fitted with its neighbours' markers in every view: matched in 3D by default, it
    stays on its own markers, and :meth:`Fitter.error` of one frame scores a posture as the
    fit did (decided on that frame, which is cluttered alike). Matched per view, this toy leg
    fits as well: what 3D gains on a real fly leg is measured (docs/benchmarks.md)."""
    cams = ring()
    body = legs()
    angles, frames = planted(body, cams, 6, seed=5, shuffle=True)
    one = legs(("a",))
    params = AnnealParams(candidates=1, threshold_mode="absolute", reanalysis_threshold=8.0,
                          error=ErrorOptions("bounded", cap_px=10.0)).with_schedule(3000)
    fitter = Fitter(one, cams, params)
    assert fitter.observations(frames).kind == "cloud"
    res = fitter.fit(frames)
    a = [body.axis_labels.index(lb) for lb in one.axis_labels]
    err = [np.linalg.norm(forward_kinematics_reference(one, r.angles_deg).markers
                          - forward_kinematics_reference(one, t[a]).markers, axis=1).max()
           for r, t in zip(res, angles, strict=True)]
    assert max(err) < 0.2, err
    assert all(r.runs >= 2 for r in res)  # matched in 3D, its runs confirm each other
    e, per_view = fitter.error(res[0].angles_deg, frames[0])
    assert e == pytest.approx(res[0].error, rel=1e-9) and not per_view.any()
