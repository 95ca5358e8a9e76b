"""The paper's accuracy set-up (Sect. 3.2): the locust hind leg seen by two orthographic
views, side and top, each a quarter of a PAL frame (360 × 288 px), 1 px per chain unit.

Used by the demo, the Table 2 benchmark and the tests, so all three score the same thing.
"""

from __future__ import annotations

from importlib.resources import as_file, files
from pathlib import Path

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


#: The paper's test video (Sect. 3.2): 668 frames of 10 concatenated movement sequences.
PAPER_FRAMES = 668
PAPER_SEQUENCES = 10
#: Table 2, both views: RMSE in degrees of each axis of the locust chain (α+β as the sum).
TABLE2_BOTH_VIEWS = {"J0.phi": 1.7, "J0.psi": 1.5, "J0.alpha": 4.7, "J1.beta": 4.9,
                     "J0.alpha+J1.beta": 0.7, "J2.gamma": 0.7}
#: The symbols Table 2 uses for those axes.
TABLE2_SYMBOLS = {"J0.phi": "φ", "J0.psi": "ψ", "J0.alpha": "α", "J1.beta": "β",
                  "J0.alpha+J1.beta": "α+β", "J2.gamma": "γ"}
#: Sect. 3.2: view error E over the test video, mean and SD (pixels), and the speeds of
#: image processing and of fitting with Table 1 (frames per second).
PAPER_VIEW_ERROR_PX = (2.9, 1.1)
PAPER_DETECTION_FPS = 8.4
PAPER_FIT_FPS = 0.4


def write_paper_project(out_dir, frames: int = PAPER_FRAMES, sequences: int = PAPER_SEQUENCES,
                        keys: int = 4, motion_seed: int = 0, options=None, progress=None):
    """Render the paper's test video (locust hind leg, side and top view, smooth random
    movement) with ground truth and a ready project config into ``out_dir``.

    ``sequences`` is capped at ``frames``; ``options`` is a
    :class:`~videotrack.synth.project.SynthOptions` (default: the paper's clean 4-px markers).
    Returns the :class:`~videotrack.synth.project.SynthProject`.
    """
    from kinematics.fileio import atomic_write_text
    from kinematics.model.chain_xml import loads_body
    from videotrack.synth.motion import smooth_random_motion
    from videotrack.synth.project import SynthOptions, write_synthetic_project

    with bundled_chain("locust_hindleg.xml") as path:
        chain_text = path.read_text(encoding="utf-8")
        body = loads_body(chain_text, source=str(path))
    angles = smooth_random_motion(body, frames, min(sequences, frames), keys, seed=motion_seed)
    project = write_synthetic_project(out_dir, body, chain_text, locust_cameras(), angles,
                                      options or SynthOptions(), progress=progress)
    # the paper's test video is fitted with the paper's settings (Table 2 reproduced)
    text = Path(project.config).read_text(encoding="utf-8")
    atomic_write_text(project.config, text + '\n[anneal]\nprofile = "paper"\n')
    return project


def write_example_project(root, trials=3, frames: int = 40, anneal=None):
    """A project folder of paper-style synthetic trials for ``videotrack batch`` (tests,
    benchmarks; ``videotrack synth DIR --trials N`` from the command line).

    ``trials`` is a count (``session<s>/trial<tt>``, ten per session) or a list of folder
    names; trial k moves with motion seed k. Returns the trial folders.
    """
    from kinematics.model.chain_xml import loads_body
    from videotrack.synth.motion import smooth_random_motion
    from videotrack.synth.project import SynthOptions, trial_names, write_synthetic_batch_project

    with bundled_chain("locust_hindleg.xml") as path:
        chain_text = path.read_text(encoding="utf-8")
        body = loads_body(chain_text, source=str(path))
    names = trial_names(trials) if isinstance(trials, int) else list(trials)
    sequences = min(PAPER_SEQUENCES, frames)
    return write_synthetic_batch_project(
        root, names, body, chain_text, locust_cameras(),
        lambda k: smooth_random_motion(body, frames, sequences, seed=k), SynthOptions(),
        anneal=anneal)
