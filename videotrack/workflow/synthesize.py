"""Artificial marker videos with known ground truth (``videotrack synth``).

:func:`synthesize` renders a chain moving through a trajectory (or given 3D marker
trajectories) through cameras and writes the videos, the truth and a project config, or a
project folder of trials for ``videotrack batch``; it returns a :class:`Synthesized`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from videotrack.errors import VideoTrackError


@dataclass(frozen=True)
class Synthesized:
    """What :func:`synthesize` wrote.

    Attributes
    ----------
    out_dir : Path
    body : str or None
        The chain's name (None for given points).
    points : int or None
        The number of given points (``points=`` only).
    cameras : tuple of str
        The views rendered, by camera name.
    frames, images : int
        Frames and images (fields, when interlaced) of one scene (0 for a batch project).
    files : tuple of Path
        The files of one scene: videos, truth, cameras, chain (if any) and project config.
    config : Path
        The config to run next: the scene's project file, or the batch project's config.
    trials : tuple of Path
        The trial folders of a batch project (empty otherwise).
    """

    out_dir: Path
    body: str | None
    points: int | None
    cameras: tuple[str, ...]
    frames: int
    images: int
    files: tuple[Path, ...]
    config: Path
    trials: tuple[Path, ...] = ()


def synthesize(
    out_dir: Path,
    options,
    *,
    chain: Path | None = None,
    cameras: Path | None = None,
    angles: Path | None = None,
    points: Path | None = None,
    trials: int | None = None,
    frames: int = 668,
    sequences: int = 10,
    keys: int = 4,
    motion_seed: int = 0,
    colours: Sequence[str] = (),
    fps: float = 50.0,
    codec: str = "ffv1",
    force: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> Synthesized:
    """Render a synthetic project into ``out_dir``.

    ``options`` is a :class:`~videotrack.synth.project.SynthOptions`; ``colours`` are
    COLOUR=MARKERS texts (:func:`~videotrack.detect.marker_colours.parse_colour`) added to its
    colours. Without ``chain`` and ``cameras`` it renders the paper's locust hind leg; with
    ``points`` (CSV or NPZ of 3D trajectories, needs ``cameras``) no chain. ``trials``: a
    project folder of that many trials instead. ``progress(done, total)`` counts rendered
    frames (trials for a batch project). Nothing is written before the outputs are checked
    against the inputs (:func:`videotrack.project.outputs.guard_outputs`).
    """
    from kinematics.cameras.files import load_cameras
    from kinematics.model.chain_xml import loads_body
    from videotrack.synth.motion import read_angles_csv, smooth_random_motion
    from videotrack.synth.paper_setup import bundled_chain, locust_cameras
    from videotrack.synth.project import write_synthetic_project

    inputs = {"chain": chain, "cameras": cameras, "angles": angles, "points": points}
    report = progress or (lambda done, total: None)
    if points is not None:
        return _write_points(out_dir, options, inputs, trials, colours, fps, codec, force,
                             report)
    if chain is None:
        with bundled_chain("locust_hindleg.xml") as path:
            chain_path, chain_text = path, Path(path).read_text(encoding="utf-8")
    else:
        chain_path = chain
        try:
            chain_text = chain.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as err:
            raise VideoTrackError(f"cannot read chain: {err}", file=chain) from None
    body = loads_body(chain_text, source=str(chain_path))
    if cameras is None:
        if chain is not None:
            raise VideoTrackError("give --cameras for your own chain", field="--cameras")
        cams = locust_cameras()
    else:
        cams = load_cameras(cameras)
    options = _with_colours(options, colours)
    if angles is None and frames < 1:
        raise VideoTrackError(f"must be at least 1, got {frames}", field="--frames")
    _guard(out_dir, options, codec, trials, inputs, list(cams), chain=True, force=force)

    def trajectory(k: int = 0):
        if angles is not None:
            return read_angles_csv(angles, body)
        return smooth_random_motion(body, frames, sequences, keys, seed=motion_seed + k)

    if trials is not None:
        return _write_batch_project(out_dir, trials, body, chain_text, cams, trajectory,
                                    options, fps, codec, report)
    motion = trajectory()
    n_frames = motion.shape[0] // (2 if options.interlaced else 1)
    project = write_synthetic_project(out_dir, body, chain_text, cams, motion, options, fps,
                                      codec, progress=lambda k: report(k, n_frames))
    return Synthesized(out_dir=out_dir, body=body.name, points=None, cameras=tuple(cams),
                       frames=n_frames, images=project.n_images,
                       files=(*project.videos, project.truth, project.cameras,
                              project.chain, project.config),
                       config=project.config)


def _with_colours(options, colours: Sequence[str]):
    from videotrack.detect.marker_colours import parse_colour

    if not colours:
        return options
    return replace(options, colours=(*options.colours,
                                     *(parse_colour(text) for text in colours)))


def _write_batch_project(out_dir, trials, body, chain_text, cameras, trajectory, options,
                         fps, codec, report) -> Synthesized:
    from videotrack.synth.project import trial_names, write_synthetic_batch_project

    if trials < 1:
        raise VideoTrackError(f"must be at least 1, got {trials}", field="--trials")
    folders = write_synthetic_batch_project(
        out_dir, trial_names(trials), body, chain_text, cameras, trajectory, options, fps,
        codec, progress=lambda k: report(k, trials))
    return Synthesized(out_dir=out_dir, body=body.name, points=None, cameras=tuple(cameras),
                       frames=0, images=0,
                       files=(out_dir / "config.toml", out_dir / "chain.xml",
                              out_dir / "cameras.toml"),
                       config=out_dir / "config.toml", trials=tuple(folders))


def _write_points(out_dir, options, inputs, trials, colours, fps, codec, force,
                  report) -> Synthesized:
    """``points``: render given 3D marker trajectories through the cameras."""
    from kinematics.cameras.files import load_camera_file
    from videotrack.synth.project import read_points, write_points_project

    given = [name for name, value in (("--chain", inputs["chain"]),
                                      ("--angles", inputs["angles"]),
                                      ("--trials", trials)) if value is not None]
    if given:
        raise VideoTrackError(f"--points draws given 3D points; it takes no {given[0]}",
                              field="--points")
    if inputs["cameras"] is None:
        raise VideoTrackError("give --cameras to draw --points through", field="--cameras")
    camera_file = load_camera_file(inputs["cameras"])
    names, points = read_points(inputs["points"])
    options = _with_colours(options, colours)
    _guard(out_dir, options, codec, None, inputs, list(camera_file.cameras), chain=False,
           force=force)
    n_frames = points.shape[0] // (2 if options.interlaced else 1)
    project = write_points_project(out_dir, names, points, camera_file.cameras, options, fps,
                                   codec, progress=lambda k: report(k, n_frames),
                                   units=camera_file.units)
    return Synthesized(out_dir=out_dir, body=None, points=len(names),
                       cameras=tuple(camera_file.cameras), frames=n_frames,
                       images=project.n_images,
                       files=(*project.videos, project.truth, project.cameras,
                              project.config),
                       config=project.config)


def _guard(out, options, codec: str, trials: int | None, inputs: dict,
           camera_names: list[str], chain: bool, force: bool) -> None:
    """Refuse to write over an input, or over an existing file of another kind unless
    ``force`` (:func:`videotrack.project.outputs.guard_outputs`), before rendering anything."""
    from videotrack.project.outputs import guard_outputs
    from videotrack.synth.project import CODECS, trial_names

    ext = CODECS[codec][1]
    videos = ([f"video_{name}{ext}" for name in camera_names] if options.layout == "separate"
              else [f"video{ext}"])
    if codec == "png":
        videos = [n if n.endswith("_png") else f"{n}_png" for n in videos]
    video_kind = "folder" if codec == "png" else "video"

    def scene(folder: Path) -> dict:
        found = {folder / n: video_kind for n in videos}
        found.update({folder / "truth.csv": "csv", folder / "cameras.toml": "toml",
                      folder / "project.toml": "toml"})
        if chain:
            found[folder / "chain.xml"] = "xml"
        return found

    if trials is not None and trials >= 1:
        outputs = {out / "config.toml": "toml", out / "chain.xml": "xml",
                   out / "cameras.toml": "toml"}
        for name in trial_names(trials):
            outputs.update({**scene(out / name), out / name / "config.toml": "toml"})
    else:
        outputs = scene(out)
    given = {path: f"the --{key} file" for key, path in inputs.items() if path}
    guard_outputs(outputs, given, force=force)
