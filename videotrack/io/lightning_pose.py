"""Lightning Pose prediction CSVs.

Lightning Pose writes its predictions in DeepLabCut's CSV layout (header rows scorer,
bodyparts, coords with x, y, likelihood) under a scorer naming the model
(``heatmap_tracker``, ``heatmap_mhcrnn_tracker``, ...), so the DeepLabCut reader reads them; this
module only recognises them.
"""

from __future__ import annotations

from pathlib import Path

from videotrack.io import dlc
from videotrack.io.keypoints import KeypointTracks


def is_lightning_pose_csv(path: Path) -> bool:
    """Whether a CSV's scorer row names a Lightning Pose model."""
    try:
        with open(path, encoding="utf-8-sig") as fh:
            first = fh.readline()
    except (OSError, UnicodeDecodeError):
        return False
    cells = [c.strip() for c in first.split(",")]
    return (len(cells) > 1 and cells[0].lower() == "scorer"
            and any(c.endswith("_tracker") for c in cells[1:]))


def read(path: Path, individual: str | int | None = None) -> KeypointTracks:
    """Read a Lightning Pose predictions CSV."""
    return dlc.read(path, individual=individual)
