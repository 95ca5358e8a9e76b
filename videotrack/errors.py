"""Errors of the video side (video files, views, filters, detections, config)."""

from kinematics.errors import LocatedError


class VideoTrackError(LocatedError):
    """A problem with a video, view, filter, detections file or project config."""


class VideoTrackWarning(UserWarning):
    """A problem VideoTrack works around (truncated video, view without markers, ...); the CLI
    prints each as one line."""
