"""The paper's accuracy set-up (Sect. 3.2): the locust hind leg seen by two orthographic
views, side and top, each a quarter of a PAL frame (360 × 288 px), 1 px per chain unit.

Used by the demo, the Table 2 benchmark and the tests, so all three score the same thing.
"""

from __future__ import annotations

from importlib.resources import as_file, files

from kinematics.cameras import OrthographicCamera

#: Image size of each view: a quarter of PAL resolution, as the paper's test video.
VIEW_SIZE = (360, 288)
#: Where the body-coxa joint (the fixed root) appears in both views.
ROOT_PIXEL = (310.0, 144.0)


def locust_cameras() -> dict[str, OrthographicCamera]:
    """Side view seen from the right (u = x, v = -y) and top view (u = x, v = z)."""
    return {
        "side": OrthographicCamera.from_axes("side", 1.0, ("x", "-y"), ROOT_PIXEL,
                                             size=VIEW_SIZE),
        "top": OrthographicCamera.from_axes("top", 1.0, ("x", "z"), ROOT_PIXEL,
                                            size=VIEW_SIZE),
    }


def bundled_chain(name: str):
    """Context manager giving a filesystem path of a chain shipped in ``videotrack.chains``."""
    return as_file(files("videotrack.chains") / name)
