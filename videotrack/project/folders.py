"""Projects: many trials in one folder tree, configured by inherited ``config.toml`` files.

Layout (documented in docs/batch.md)::

    PROJECT/
      config.toml               what every trial shares, and the [batch] keys
      chain.xml, cameras.toml   whatever config.toml names (paths relative to it)
      summary.csv               written by 'videotrack batch'
      logs/                     one log file per batch run
      SESSION/
        config.toml             optional: overrides for the trials of this session
        TRIAL/
          config.toml           optional: overrides for this trial
          walk.avi              the trial's video(s), found by [batch] videos
          walk.detections.npz   outputs, beside the video
          walk.results.csv (+ .json, .png)

Trial folders are found by the ``[batch] trials`` glob patterns (default ``*/*``). A trial's
config is every ``config.toml`` from the project folder down to the trial folder, merged by
:func:`videotrack.project.config.merge_layers` (deeper files override keys; lists and arrays of
tables
replace); each file is checked on its own first, so an error names the file that has the bad
key, and relative paths resolve against the file that set them. ``[video] path`` is the
trial's videos (or set in the trial's own config.toml).
"""

from __future__ import annotations

import fnmatch
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from kinematics.errors import LocatedError
from videotrack.errors import VideoTrackError
from videotrack.project.config import (
    Config,
    Key,
    Section,
    config_from_layers,
    merge_layers,
    parse_layer,
    read_toml,
    register_section,
)

#: The name of every config file of a project tree.
CONFIG_NAME = "config.toml"
#: Folder of the batch run logs, in the project folder.
LOGS_NAME = "logs"
#: [batch] keys that describe the whole project: only the project's own config.toml has them.
PROJECT_KEYS = ("trials", "jobs", "summary")


def _patterns_rule(patterns: list) -> str | None:
    for p in patterns:
        if not p or PurePosixPath(p).is_absolute() or ".." in PurePosixPath(p).parts:
            return f"patterns must be relative and stay inside the project, got {p!r}"
    return None


BATCH = register_section(Section("batch", (
    Key("trials", "list[str]", ["*/*"], "Glob patterns of the trial folders, relative to the "
        "project folder ('*/*': PROJECT/SESSION/TRIAL; '*': PROJECT/TRIAL; '.': the project "
        "folder is the one trial). A folder without a video is not a trial. Project "
        "config.toml only.", check=_patterns_rule),
    Key("videos", "list[str]", ["*.avi", "*.mp4", "*.mov", "*.mkv"], "File-name patterns of "
        "a trial's videos in its folder; several matches are synchronised cameras, in name "
        "order (a view's 'video' index). Ignored where [video] path is set in the trial's "
        "own config.toml.", check=_patterns_rule),
    Key("keypoints", "list[str]", [], "File-name patterns of a trial's 2D keypoint files "
        "(e.g. ['*DLC*.csv'] or ['*.slp']), one per camera in name order: a folder with such "
        "files and no video is a trial of the markerless route ([keypoints] files set for "
        "it). Empty: trials are found by their videos only. Ignored where [keypoints] files "
        "is set in the trial's own config.toml.", check=_patterns_rule),
    Key("jobs", "int", 0, "Trials processed at the same time, one process each; 0: one per "
        "core. --jobs overrides. Project config.toml only.", min=0, max=4096),
    Key("summary", "path", "summary.csv", "Project summary table (CSV), relative to the "
        "project's config.toml. Project config.toml only."),
), doc="How 'videotrack batch' finds the trials of a project (see docs/batch.md)."))


@dataclass(frozen=True)
class TrialOutputs:
    """Where a trial's results go (beside its videos unless its config says otherwise)."""

    detections: Path
    results: Path
    plot: Path

    def files(self) -> tuple[Path, ...]:
        """Every file a finished trial has, checkpoints of an interrupted fit included."""
        from videotrack.results.files import sidecar_path
        from videotrack.workflow import checkpoint_paths

        return (self.detections, self.results, sidecar_path(self.results), self.plot,
                *checkpoint_paths(self.results))


def trial_outputs(config: Config) -> TrialOutputs:
    """The detections, results and plot paths of a (trial) config."""
    from videotrack.detect.run import default_output
    from videotrack.workflow import default_plot_path, default_results_path

    detections = default_output(config)
    results = default_results_path(config, detections)
    return TrialOutputs(detections, results, default_plot_path(results))


@dataclass(frozen=True)
class Trial:
    """One trial of a project: a folder, its merged config, or why it cannot run.

    ``name`` is the folder relative to the project (``session1/trial01``); ``error`` is a
    one-line message (the config could not be built) and ``config`` is then None.
    """

    name: str
    folder: Path
    config: Config | None
    error: str | None = None


@dataclass(frozen=True)
class Project:
    """A project folder: its config, ``[batch]`` keys, trials and ignored folders.

    ``ignored`` holds ``(folder, why)`` of folders the trial patterns match that are no trial
    (no video in them).
    """

    root: Path
    config_path: Path
    batch: dict
    trials: tuple[Trial, ...]
    ignored: tuple[tuple[Path, str], ...] = ()

    @property
    def logs(self) -> Path:
        return self.root / LOGS_NAME

    @property
    def summary_path(self) -> Path:
        path = Path(self.batch["summary"])  # the default is not resolved by validation
        return path if path.is_absolute() else self.root / path

    def select(self, patterns: Sequence[str]) -> tuple[Trial, ...]:
        """Trials whose names match any of the glob ``patterns`` (all when none)."""
        if not patterns:
            return self.trials
        for p in patterns:
            if not any(fnmatch.fnmatchcase(t.name, p) for t in self.trials):
                names = ", ".join(t.name for t in self.trials[:5])
                more = ", ..." if len(self.trials) > 5 else ""
                raise VideoTrackError(f"no trial matches {p!r} (trials: {names}{more})",
                                      file=self.root)
        return tuple(t for t in self.trials if any(fnmatch.fnmatchcase(t.name, p)
                                                   for p in patterns))


def open_project(path: str | os.PathLike) -> Project:
    """Find the trials of a project folder (or of its ``config.toml``) and build their configs.

    A config file with an error makes every trial under it fail with that error (the others
    still run); an error in the project's own config.toml raises.

    Raises
    ------
    VideoTrackError
        No project config, an error in it, or trial patterns that match nothing.
    """
    from videotrack.detect.video import natural_key

    path = Path(path).absolute()
    root = path.parent if path.is_file() else path
    config_path = root / CONFIG_NAME
    if not root.is_dir():
        raise VideoTrackError("no such project folder", file=root)
    if not config_path.is_file():
        raise VideoTrackError(f"no {CONFIG_NAME}: a project folder holds a {CONFIG_NAME} "
                              "with the settings its trials share (see docs/batch.md)",
                              file=root)
    layers = _LayerCache()
    root_layer = layers.get(config_path)  # raises: nothing runs with a broken project config
    batch = BATCH.validate(root_layer.get("batch", {}), file=config_path, base=root)
    folders: dict[Path, None] = {}
    for pattern in batch["trials"]:
        # "." (a single trial: the project folder itself) is no glob pattern to pathlib
        for folder in [root] if PurePosixPath(pattern) == PurePosixPath(".") else root.glob(
                pattern):
            rel = folder.relative_to(root).parts
            if folder.is_dir() and not any(p.startswith(".") for p in rel) and (
                    not rel or rel[0] != LOGS_NAME):
                folders[folder] = None
    trials, ignored = [], []
    for folder in sorted(folders, key=lambda f: natural_key(f.relative_to(root).as_posix())):
        name = folder.relative_to(root).as_posix()
        try:
            config = _trial_config(root, folder, layers)
        except _NoVideo as why:
            ignored.append((folder, str(why)))
            continue
        except LocatedError as err:
            trials.append(Trial(name, folder, None, str(err)))
            continue
        trials.append(Trial(name, folder, config))
    if not trials:
        raise VideoTrackError(
            f"no trial: no folder matching [batch] trials {batch['trials']} holds a video "
            f"matching [batch] videos (or keypoint files matching [batch] keypoints)",
            file=config_path, field="batch.trials")
    return Project(root, config_path, batch, _claim_outputs(trials), tuple(ignored))


class _NoVideo(Exception):
    """A folder the trial patterns match holds no video: it is not a trial."""


class _LayerCache:
    """Checked layers by file, read once (sessions share their config files)."""

    def __init__(self) -> None:
        self.layers: dict[Path, dict | LocatedError] = {}

    def get(self, path: Path) -> dict:
        if path not in self.layers:
            try:
                self.layers[path] = parse_layer(read_toml(path), path)
            except LocatedError as err:
                self.layers[path] = err
        found = self.layers[path]
        if isinstance(found, LocatedError):
            raise found
        return found


def _trial_config(root: Path, folder: Path, layers: _LayerCache) -> Config:
    """The merged config of a trial folder (see the module docstring)."""
    rel = folder.relative_to(root).parts
    chain = [root.joinpath(*rel[:k]) for k in range(len(rel) + 1)]  # root down to the trial
    files = [f / CONFIG_NAME for f in chain if (f / CONFIG_NAME).is_file()]
    stack = [layers.get(f) for f in files]
    for file, layer in zip(files[1:], stack[1:], strict=True):
        for key in PROJECT_KEYS:
            if key in layer.get("batch", {}):
                raise VideoTrackError(f"a project-wide key: set it in {root / CONFIG_NAME}",
                                      file=file, field=f"batch.{key}")
    merged = merge_layers(stack)
    own = folder / CONFIG_NAME
    extra = []
    keypoints = _trial_keypoints(folder, files, stack, merged)
    if keypoints is not None:  # the markerless route: no video needed
        if keypoints:
            extra = [parse_layer({"keypoints": {"files": [str(p) for p in keypoints]}}, own)]
    elif "path" in merged.get("video", {}):
        setter = [f for f, layer in zip(files, stack, strict=True)
                  if "path" in layer.get("video", {})][-1]
        if setter != own:
            raise VideoTrackError(
                "set above the trial folder, so every trial would read the same video: set "
                "it in a trial's own config.toml, or leave it out and let [batch] videos "
                "find each trial's videos", file=setter, field="video.path")
    else:
        patterns = merged.get("batch", {}).get("videos", BATCH.key("videos").default)
        videos = _find_videos(folder, patterns)
        if not videos:
            raise _NoVideo(f"no video matching {', '.join(patterns)}")
        value = [str(v) for v in videos] if len(videos) > 1 else str(videos[0])
        extra = [parse_layer({"video": {"path": value}}, own)]
    return config_from_layers([*stack, *extra], files[-1], base=folder, sources=files)


def _trial_keypoints(folder: Path, files: list[Path], stack: list, merged: Mapping
                     ) -> list[Path] | None:
    """A markerless trial's keypoint files: [] when the trial's own config.toml sets
    ``[keypoints] files``, those matching ``[batch] keypoints`` when the folder has no video,
    None for a trial of the marker route. A keypoint list set above the trial folder would
    make every trial read the same files: refused, as for videos."""
    setters = [f for f, layer in zip(files, stack, strict=True)
               if layer.get("keypoints", {}).get("files")]
    if setters:
        if setters[-1] != folder / CONFIG_NAME:
            raise VideoTrackError(
                "set above the trial folder, so every trial would read the same keypoint "
                "files: set them in a trial's own config.toml, or let [batch] keypoints find "
                "each trial's files", file=setters[-1], field="keypoints.files")
        return []
    patterns = merged.get("batch", {}).get("keypoints", [])
    if not patterns or "path" in merged.get("video", {}):
        return None
    videos = merged.get("batch", {}).get("videos", BATCH.key("videos").default)
    if _find_videos(folder, videos):
        return None
    found = _find_videos(folder, patterns)
    return found or None


def _find_videos(folder: Path, patterns: Sequence[str]) -> list[Path]:
    from videotrack.detect.video import natural_key

    found = {p for pattern in patterns for p in folder.glob(pattern)
             if not p.name.startswith(".")}  # hidden: temporary files of unfinished writes
    return sorted(found, key=lambda p: natural_key(p.name))


def _claim_outputs(trials: list[Trial]) -> tuple[Trial, ...]:
    """Trials whose outputs would overwrite another trial's (e.g. an ``[output] detections``
    set in a shared config.toml), or a file some trial reads (its video, a config, the
    chain, ...), fail instead."""
    owners: dict[Path, list[int]] = {}
    outputs = {}
    for i, trial in enumerate(trials):
        if trial.config is None:
            continue
        try:
            outputs[i] = trial_outputs(trial.config)
        except LocatedError as err:
            trials[i] = Trial(trial.name, trial.folder, None, str(err))
            continue
        for path in (outputs[i].detections, outputs[i].results):
            owners.setdefault(path, []).append(i)
    read = _inputs_of(trials)
    for path, claim in owners.items():
        plain = Path(os.path.normpath(path.absolute()))
        if plain in read:
            for i in claim:
                t = trials[i]
                trials[i] = Trial(t.name, t.folder, None, str(VideoTrackError(
                    f"is {read[plain]} of the project: an output never replaces an input; "
                    "set [output] detections / [fit] results to another path", file=plain)))
            continue
        if len(claim) < 2:
            continue
        names = ", ".join(trials[i].name for i in claim)
        for i in claim:
            t = trials[i]
            trials[i] = Trial(t.name, t.folder, None, str(VideoTrackError(
                f"trials {names} would all write this file: leave [output] detections and "
                "[fit] results empty in shared config files (outputs then go beside each "
                "trial's video)", file=path)))
    return tuple(trials)


def _inputs_of(trials: list[Trial]) -> dict[Path, str]:
    """Every file the trials read (configs, videos, chains, cameras), absolute, by what it
    is."""
    from videotrack.batch import project_inputs

    return {Path(os.path.normpath(Path(p).absolute())): what
            for p, what in project_inputs(trials).items()}


def load_trial_config(project: str | os.PathLike, name: str) -> Config:
    """The merged config of one trial, by its name (``session1/trial01``), as ``batch``
    builds it; for ``videotrack detect/fit/run PROJECT --trial NAME``.

    Raises
    ------
    VideoTrackError
        No such trial, or the trial's config has an error.
    """
    proj = open_project(project)
    for trial in proj.trials:
        if trial.name == Path(name).as_posix().strip("/"):
            if trial.config is None:
                raise VideoTrackError(trial.error or "no config")
            return trial.config
    names = ", ".join(t.name for t in proj.trials[:5]) + (", ..." if len(proj.trials) > 5
                                                           else "")
    raise VideoTrackError(f"no trial {name!r} (trials: {names})", file=proj.root,
                          field="--trial")


def command_config(path: str | os.PathLike, trial: str | None) -> Config:
    """The config a command works on: a project file, or with ``trial`` that trial of the
    project folder ``path``."""
    from videotrack.project.config import load_config

    return load_config(path) if trial is None else load_trial_config(path, trial)
