"""Project configuration: a TOML file checked against small declarative schemas.

Every section of the project file is declared once, in :mod:`videotrack.project.sections` or by
the module that owns it, as a :class:`Section` of :class:`Key` entries (name, type, default,
bounds, doc) — the schema mechanism of :mod:`videotrack.project.schema`. The declarations are the
single source of truth: :func:`load_config` validates against them, the records built from a
config (e.g. :class:`~videotrack.detect.markers.MarkerSettings`) validate through them, and
:func:`describe_section` turns them into a Markdown reference.

A later module adds its section with ``register_section(Section("name", [...]))`` at import
and reads ``config["name"]``; the module must be imported before :func:`load_config` (the
commands that read a section import its module). A section can also be derived from a frozen
settings record whose fields carry their metadata (:func:`record_section`, used for
``[anneal]`` from :class:`kinematics.fit.settings.AnnealParams`); :func:`record_from_table` builds
the record back from the checked section.

Inheritance (projects, :mod:`videotrack.project.folders`): each file is first checked on its own by
:func:`parse_layer` (unknown keys, types and values are reported against the file that has
them; relative paths resolve against it), the layers are merged by :func:`merge_layers` (a
deeper file overrides keys of the one above; lists and arrays of tables replace), and
:func:`config_from_layers` fills defaults and checks required keys. :func:`load_config` is the
one-layer case.

This module reads, merges and checks files; the schema mechanism (type strings, error
messages) and the sections live in the two modules named above, and every public name of
both is importable from here.
"""

from __future__ import annotations

import copy
import dataclasses
import os
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from kinematics.fileio import parse_toml
from videotrack.errors import VideoTrackError
from videotrack.project.schema import (  # noqa: F401  (the public names of the schema)
    REQUIRED,
    SECTIONS,
    Key,
    RecordKey,
    Section,
    Variants,
    _kind,
    describe_section,
    record_from_table,
    record_keys,
    record_section,
    register_section,
)
from videotrack.project.sections import (  # noqa: F401  (registers the sections)
    ANNEAL,
    CAMERAS,
    CHAIN,
    FILTER_STEPS,
    FILTERS,
    FIT,
    KEYPOINT_ROUTES,
    KEYPOINTS,
    MARKERS,
    OUTPUT,
    TRIANGULATION_INITS,
    TRIANGULATION_METHODS,
    VIDEO,
    VIEWS,
    anneal_from_table,
)


@dataclass(frozen=True)
class Config:
    """A validated project file: ``config["video"]`` is the checked dict of that section.

    An absent section holds its defaults (an absent array of tables is an empty list);
    ``given`` lists the sections the file itself has, ``keys_given`` the keys it sets in each
    (table) section. A config merged from several files
    (:func:`config_from_layers`) lists them in ``sources``, top first; ``base``, when set, is
    its :attr:`folder` instead of the folder of ``path`` (a trial folder of a project).
    """

    path: Path
    sections: Mapping[str, Any]
    given: tuple[str, ...] = ()
    sources: tuple[Path, ...] = ()
    base: Path | None = None
    keys_given: Mapping[str, tuple[str, ...]] = dataclasses.field(default_factory=dict)

    @property
    def folder(self) -> Path:
        """Where default outputs go: ``base`` if set, else the folder of ``path``."""
        return self.base if self.base is not None else self.path.parent

    def __getitem__(self, name: str):
        return self.sections[name]

    def __contains__(self, name: str) -> bool:
        return name in self.sections


def updated_toml_text(text: str, table: Mapping) -> str:
    """``text`` (a TOML document) changed to hold ``table``, keeping its comments, order and
    formatting wherever a value did not change (a project file a person wrote and commented,
    saved again by the GUI). Keys ``table`` lacks are removed; an array of tables that
    changed is replaced whole."""
    import tomlkit

    doc = tomlkit.parse(text)
    _sync(doc, table)
    return tomlkit.dumps(doc)


def _sync(container, table: Mapping) -> None:
    for key in [k for k in container if k not in table]:
        del container[key]
    for key, value in table.items():
        if key in container and isinstance(value, Mapping) and isinstance(
                container[key], Mapping):
            _sync(container[key], value)
        elif key not in container or container[key] != value:
            container[key] = value


def load_config(path: str | os.PathLike) -> Config:
    """Read and validate a project TOML file.

    Raises
    ------
    VideoTrackError
        Missing or unreadable file, TOML syntax (with the line), unknown section or key, wrong
        type or value.
    """
    path = Path(path).absolute()
    return config_from_layers([parse_layer(read_toml(path), path)], path)


def parse_config(text: str, path: str | os.PathLike) -> Config:
    """Validate TOML ``text`` as if read from ``path`` (relative paths resolve beside it)."""
    path = Path(path).absolute()
    return config_from_layers([parse_layer(loads_toml(text, path), path)], path)


def read_toml(path: str | os.PathLike) -> dict:
    """The raw tables of a TOML file; a missing file or a syntax error (with its line) raises
    :class:`VideoTrackError`."""
    path = Path(path).absolute()
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise VideoTrackError("no such config file", file=path) from None
    except (OSError, UnicodeDecodeError) as err:
        raise VideoTrackError(f"cannot read config file: {err}", file=path) from None
    return loads_toml(text, path)


def loads_toml(text: str, path: str | os.PathLike) -> dict:
    """:func:`read_toml` for text already read from ``path``."""
    try:
        return parse_toml(text)
    except tomllib.TOMLDecodeError as err:
        msg = str(err)
        match = re.search(r"\(at line (\d+), column \d+\)", msg)
        line = int(match.group(1)) if match else None
        msg = re.sub(r"\s*\(at line \d+, column \d+\)", "", msg)
        raise VideoTrackError(f"TOML syntax: {msg}", file=path, line=line) from None


def parse_layer(raw: Mapping, path: str | os.PathLike) -> dict:
    """Check the tables of one config file on their own, before merging.

    Unknown sections and keys, wrong types and bad values are errors naming ``path``;
    relative paths are resolved against its folder; missing keys stay missing (a file
    deeper in a project need only hold what it changes). Each table of an array
    (``[[views]]``) is checked completely, because an array replaces the one above.

    Returns
    -------
    dict
        Section name -> checked keys (a list of checked tables for an array section).
    """
    path = Path(path).absolute()
    unknown = [k for k in raw if k not in SECTIONS]
    if unknown:
        raise VideoTrackError(
            f"unknown section (known: {', '.join(SECTIONS)})", file=path, field=unknown[0]
        )
    layer: dict[str, Any] = {}
    for name, value in raw.items():
        section = SECTIONS[name]
        if section.array:
            if not isinstance(value, list):
                raise VideoTrackError(
                    f"must be an array of tables ([[{name}]]), got {_kind(value)}",
                    file=path,
                    field=name,
                )
            layer[name] = [
                section.validate(item, where=f"{name}[{i}]", file=path, base=path.parent)
                for i, item in enumerate(value)
            ]
        else:
            layer[name] = section.validate(value, file=path, base=path.parent, partial=True)
    return layer


def merge_layers(layers: Sequence[Mapping]) -> dict:
    """Merge checked layers (:func:`parse_layer`), later ones overriding earlier ones.

    A section merges key by key; a key's value replaces the one above whole, also when it
    is a list or an array of tables (``[[views]]``, ``[[filters.steps]]``): a deeper file
    that has ``[[views]]`` defines all views anew.
    """
    merged: dict[str, Any] = {}
    for layer in layers:
        for name, value in layer.items():
            if isinstance(value, Mapping) and isinstance(merged.get(name), Mapping):
                merged[name] = {**merged[name], **value}
            else:
                merged[name] = copy.deepcopy(value)
    return merged


def config_from_layers(
    layers: Sequence[Mapping],
    path: str | os.PathLike,
    *,
    base: str | os.PathLike | None = None,
    sources: Sequence[str | os.PathLike] = (),
) -> Config:
    """Merge checked layers and validate the result: defaults filled, required keys checked.

    ``path`` is the file errors of the merged config are reported against (the deepest
    file), ``base`` the folder default outputs go to (default: the folder of ``path``),
    ``sources`` the files merged, top first.
    """
    path = Path(path).absolute()
    merged = _markerless_defaults(merge_layers(layers))
    sections: dict[str, Any] = {}
    for name, section in SECTIONS.items():
        value = merged.get(name)
        if section.array:
            sections[name] = [
                section.validate(item, where=f"{name}[{i}]", file=path, base=path.parent)
                for i, item in enumerate(value or [])
            ]
        else:
            sections[name] = section.validate(value or {}, file=path, base=path.parent)
    given = tuple(dict.fromkeys(name for layer in layers for name in layer))
    keys_given = {name: tuple(value) for name, value in merged.items()
                  if isinstance(value, Mapping)}
    return Config(path=path, sections=sections, given=given,
                  sources=tuple(Path(s) for s in sources) or (path,),
                  base=Path(base) if base is not None else None, keys_given=keys_given)


def _markerless_defaults(merged: Mapping) -> dict:
    """A project fitted to keypoint files (``[keypoints] files``) detects no markers: its
    ``[video] path`` and ``[[filters.steps]]`` may be left out (they are then empty)."""
    out = dict(merged)
    if (merged.get("keypoints") or {}).get("files"):
        out["video"] = {"path": "", **(merged.get("video") or {})}
        out["filters"] = {"steps": [], **(merged.get("filters") or {})}
    return out
