"""Where markers are matched: in each view (Eq. 5) or in 3D after triangulation
(``match`` 'auto' decides on the data).
"""

from __future__ import annotations

import numpy as np

from kinematics.fit.status import marker_images
from kinematics.observe.cloud import cloud_observations, view_groups
from kinematics.observe.observations import Observations


class MatchMixin:
    """The :class:`~kinematics.fit.Fitter`'s match policy."""

    def match_for(self, data) -> str:
        """Where these data's markers are matched: 'views' (Eq. 5, each view on its own) or
        '3d' (triangulated first): :meth:`match_why`'s first answer."""
        return self.match_why(data)[0]

    def match_why(self, data) -> tuple[str, str]:
        """Where these data's markers are matched ('views' or '3d') and why, in a few words.

        ``match`` says, or with 'auto' the data. With 3 or more views (of each colour): '3d'
        for a body annealed in several partitions (many limbs); for a single chain, '3d'
        where its views hold more than ``Tuning.clutter_ratio`` detections per marker image
        (other limbs' markers: :meth:`clutter`) or where the triangulated points cover its
        markers in at least ``Tuning.covered_share`` of the frames (:meth:`covered`), else
        'views'. Labelled keypoints are matched by their labels in the views ('views'); 3D
        points are '3d'. A fit of some frames decides on all the data it is given, so pass
        a video's whole detections (and ``frames``) for its frames to be matched alike; a
        one-frame call (:meth:`fit_frame`, :meth:`error`) decides on that frame, unless
        ``match`` is set (the GUI sets it from the whole video)."""
        if isinstance(data, Observations) and data.kind != "points":
            return ("3d", "3D points") if data.kind in ("cloud", "points3d") else (
                "views", "labelled keypoints")
        p = self.params
        if p.match != "auto":
            return p.match, f"match = {p.match!r}"
        if self._views_3d < 3:
            return "views", "fewer than 3 views to triangulate from"
        if not self.match_measured:
            return "3d", "a body of several limbs"
        obs = data if isinstance(data, Observations) else self._unlabelled(data)
        if obs.hidden is not None:  # marked per view (the GUI's H): kept per view
            return "views", "markers marked hidden in a view"
        clutter = self.clutter(obs)
        if clutter > self.tuning.clutter_ratio:
            return "3d", (f"{clutter:.1f} detections per marker image, other limbs' markers "
                          f"(above {self.tuning.clutter_ratio:g})")
        covered = self.covered(obs)
        return ("3d" if covered >= self.tuning.covered_share else "views"), (
            f"every marker triangulated in {100 * covered:.0f} % of the frames (3D from "
            f"{100 * self.tuning.covered_share:.0f} %)")

    @property
    def match_measured(self) -> bool:
        """Whether :meth:`match_for` decides on the data: ``match`` 'auto' for a single
        chain (one partition) in 3 or more views."""
        p = self.params
        return p.match == "auto" and self._views_3d >= 3 and not self._limbs(p)

    def clutter(self, data) -> float:
        """Unlabelled detections per marker image the views show: the median over the frames
        with any (0 without any); what 'auto' :meth:`match_for` reads for a single chain."""
        obs = data if isinstance(data, Observations) else self._unlabelled(data)
        shown = obs.with_unseen(self.unseen) if self.unseen is not None else obs
        frames = np.arange(obs.n_frames)
        images = marker_images(shown, frames, len(self.body.marker_names))
        found = obs.view_counts(frames).sum(axis=1)
        keep = (images > 0) & (found > 0)
        return float(np.median(found[keep] / images[keep])) if keep.any() else 0.0

    def covered(self, data) -> float:
        """The share of frames with detections whose triangulated points are at least as
        many as the body's markers (:func:`~kinematics.observe.cloud.cloud_observations`; on up to
        ``Tuning.match_sample`` frames spread over the video): where it is low, markers are
        often absent or seen by fewer than 3 views, and matching in 3D lets a limb fold onto
        the points that are there (docs/fitting.md, 'When the defaults match in 3D')."""
        obs = data if isinstance(data, Observations) else self._unlabelled(data)
        seen = np.flatnonzero(obs.view_counts(np.arange(obs.n_frames)).sum(axis=1) > 0)
        if seen.size == 0 or self._views_3d < 3:
            return 0.0
        pick = seen[np.unique(np.linspace(0, seen.size - 1, min(self.tuning.match_sample, seen.size)
                                          ).astype(int))]
        cloud = cloud_observations(self.cameras, obs.take(pick), self.unseen)
        points = (cloud.points3d[:, :, 3] > 0).sum(axis=1)
        return float(np.mean(points >= len(self.body.marker_names)))

    @property
    def _views_3d(self) -> int:
        """The views a marker can be triangulated from: all, or with ``view_markers`` the
        fewest that show the same markers (one colour's views)."""
        if self.unseen is None:
            return self.n_views
        return min((len(g) for g in view_groups(self.unseen)), default=0)
