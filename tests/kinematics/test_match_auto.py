"""``match = "auto"`` decides on the data: a single chain whose views hold many more
detections than it has markers (other limbs' markers), or whose markers are triangulated in
nearly every frame, is matched in 3D, one whose markers are often absent per view, and a frame
of the fit is scored as the fit scored it."""

from __future__ import annotations

import numpy as np
import pytest

from kinematics.fit import AnnealParams, Fitter
from kinematics.fit.settings import ErrorOptions
from kinematics.fit.tuning import TUNING
from kinematics.model import Body, Chain, Root
from kinematics.model.fk import forward_kinematics_reference
from kinematics.observe.observations import Observations
from tests.fixtures.bodies import leg
from tests.fixtures.cameras import ring
from tests.fixtures.planted import planted_postures

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


def without_tip(frames, which):
    """Frames (in marker order) with the tip (the second marker) absent from every view in
    the frames ``which``."""
    return [[v[:1] for v in f] if i in which else f for i, f in enumerate(frames)]


def test_auto_matches_a_chain_in_3d_where_its_views_hold_other_limbs_markers():
    cams = ring()
    one = Fitter(legs(("a",)), cams)
    _, among = planted_postures(legs(), cams, 4, seed=1, shuffle=True)  # 6 markers drawn, 2 fitted
    assert one.match_for(among) == "3d" and one.observations(among).kind == "cloud"
    assert "3.0 detections per marker image" in one.match_why(among)[1]
    # the bound, on a chain whose tip is never seen (so its markers are never all
    # triangulated): detections per marker image, median over the frames
    _, alone = planted_postures(legs(("a",)), cams, 4, seed=1)
    absent = without_tip(alone, range(4))
    assert one.covered(absent) == 0.0 and one.match_for(absent) == "views"
    below = with_extra(absent, int(2 * TUNING.clutter_ratio) - 1)  # (1 + 3) / 2 = the bound
    assert one.clutter(below) == TUNING.clutter_ratio and one.match_for(below) == "views"
    assert one.match_for(with_extra(absent, int(2 * TUNING.clutter_ratio))) == "3d"
    # 3D needs 3 views; a setting overrides; labelled data are not matched
    two = Fitter(legs(("a",)), dict(list(cams.items())[:2]))
    assert two.match_for([f[:2] for f in among]) == "views"
    views = Fitter(legs(("a",)), cams, AnnealParams(match="views"))
    assert views.match_why(among) == ("views", "match = 'views'")
    pts = Observations.points_3d(np.zeros((1, 2, 3)), ["a_knee_mk", "a_tip"],
                                 ["a_knee_mk", "a_tip"])
    assert one.match_for(pts) == "3d"
    # several limbs are matched in 3D whatever the data
    assert Fitter(legs(), cams).match_why(absent) == ("3d", "a body of several limbs")


def test_auto_matches_a_chain_seen_alone_in_3d_where_its_markers_are_triangulated():
    """A chain alone in its views: in 3D where the triangulated points cover its markers in
    TUNING.covered_share of the frames, per view where markers are often absent (a limb folds onto
    the points left in 3D: the free mouse of docs/benchmarks.md)."""
    cams = ring()
    one = Fitter(legs(("a",)), cams)
    _, alone = planted_postures(legs(("a",)), cams, 40, seed=2)
    assert one.covered(alone) == 1.0 and one.match_for(alone) == "3d"
    few = int(len(alone) * (1 - TUNING.covered_share) / 2)  # absent in half the share allowed
    assert one.match_for(without_tip(alone, range(few))) == "3d"
    many = 2 * int(len(alone) * (1 - TUNING.covered_share))  # ... in twice that share
    assert one.covered(without_tip(alone, range(many))) == 1 - many / len(alone)
    how, why = one.match_why(without_tip(alone, range(many)))
    assert how == "views" and "every marker triangulated in 90 % of the frames" in why


def test_a_leg_among_others_fitted_with_the_defaults_and_scored_alike():
    """One leg fitted with its neighbours' markers in every view: matched in 3D by default, it
    stays on its own markers, and :meth:`Fitter.error` of one frame scores a posture as the
    fit did (decided on that frame, which is cluttered alike). Matched per view, this toy leg
    fits as well: what 3D gains on a real fly leg is measured (docs/benchmarks.md)."""
    cams = ring()
    body = legs()
    angles, frames = planted_postures(body, cams, 6, seed=5, shuffle=True)
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


def test_markers_hidden_by_hand_keep_a_chain_per_view():
    """Marks of the GUI's H say a marker is hidden in one view, which only the per-view match
    can honour: a chain 'auto' would match in 3D is then matched per view, and its E of one
    frame with marks equals that of the per-view match."""
    cams = ring()
    one = Fitter(legs(("a",)), cams)
    angles, alone = planted_postures(legs(("a",)), cams, 3, seed=4)
    assert one.match_for(alone) == "3d"
    marks = np.zeros((len(cams), 2), bool)
    marks[1, 1] = True  # the tip, in the second view
    obs = one._unlabelled(alone).with_hidden(np.broadcast_to(marks, (3, *marks.shape)))
    assert one.match_why(obs) == ("views", "markers marked hidden in a view")
    views = Fitter(legs(("a",)), cams, AnnealParams(match="views"))
    e = one.error(angles[0], alone[0], hidden=marks)
    assert e[0] == views.error(angles[0], alone[0], hidden=marks)[0] and e[1].any()
