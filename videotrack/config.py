"""Project configuration: a TOML file checked against small declarative schemas.

Every section of the project file is declared once, here or by the module that owns it, as a
:class:`Section` of :class:`Key` entries (name, type, default, bounds, doc). The declarations are
the single source of truth: :func:`load_config` validates against them, the records built from
a config (e.g. :class:`~videotrack.markers.MarkerSettings`) validate through them, and
:func:`describe_section` turns them into a Markdown reference.

A later module adds its section with ``register_section(Section("name", [...]))`` at import
and reads ``config["name"]``; the module must be imported before :func:`load_config` (the
commands that read a section import its module). A section can also be derived from a frozen
settings record whose fields carry their metadata (:func:`record_section`, used for
``[anneal]`` from :class:`kinematics.settings.AnnealParams`); :func:`record_from_table` builds
the record back from the checked section.

Inheritance (projects, :mod:`videotrack.project`): each file is first checked on its own by
:func:`parse_layer` (unknown keys, types and values are reported against the file that has
them; relative paths resolve against it), the layers are merged by :func:`merge_layers` (a
deeper file overrides keys of the one above; lists and arrays of tables replace), and
:func:`config_from_layers` fills defaults and checks required keys. :func:`load_config` is the
one-layer case.

Type strings
    ``str``, ``int``, ``float`` (an integer is accepted), ``bool``, ``path`` (a string, resolved
    against the config file's folder), ``table`` (a TOML table), ``list[T]`` for any type T, and
    unions ``A | B``.

Errors name the file and the dotted key: ``run.toml: filters.steps[2].value: must be at most
255, got 300``.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import os
import re
import tomllib
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from kinematics.errors import LocatedError
from kinematics.settings import PROFILES, AnnealParams
from videotrack.errors import VideoTrackError

#: Marks a key without a default: it must be given.
REQUIRED = object()


@dataclass(frozen=True)
class Key:
    """One key of a section.

    ``min``/``max`` bound every number inside the value (also inside lists); ``length`` fixes the
    length of a list; ``check`` is an extra rule returning an error message or None; ``items`` is
    the schema (a :class:`Section` or :class:`Variants`) of a ``table`` or ``list[table]``.
    """

    name: str
    type: str
    default: Any = REQUIRED
    doc: str = ""
    choices: tuple | None = None
    min: float | None = None
    max: float | None = None
    length: int | None = None
    check: Callable[[Any], str | None] | None = None
    items: Section | Variants | None = None

    @property
    def required(self) -> bool:
        return self.default is REQUIRED


@dataclass(frozen=True)
class Section:
    """A table of keys; ``array`` True for an array of tables (``[[views]]``)."""

    name: str
    keys: tuple[Key, ...]
    doc: str = ""
    array: bool = False
    _by_name: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "keys", tuple(self.keys))
        object.__setattr__(self, "_by_name", {k.name: k for k in self.keys})

    def key(self, name: str) -> Key:
        return self._by_name[name]

    def validate(
        self,
        table: Mapping,
        *,
        where: str | None = None,
        file: str | os.PathLike | None = None,
        base: str | os.PathLike | None = None,
        partial: bool = False,
    ) -> dict:
        """Check ``table`` and return a new dict with defaults filled in and paths resolved.

        ``where`` is the dotted prefix used in error fields (default: the section name),
        ``base`` the folder relative paths resolve against (default: the working directory).
        ``partial`` checks only the keys present and adds no defaults (one layer of an
        inherited config; see :func:`parse_layer`).
        """
        where = self.name if where is None else where
        if not isinstance(table, Mapping):
            raise VideoTrackError(f"must be a table, got {_kind(table)}", file=file, field=where)
        unknown = [k for k in table if k not in self._by_name]
        if unknown:
            known = ", ".join(self._by_name) or "none"
            raise VideoTrackError(
                f"unknown key {unknown[0]!r} (known keys: {known})",
                file=file,
                field=f"{where}.{unknown[0]}",
            )
        out = {}
        for key in self.keys:
            name = f"{where}.{key.name}"
            if key.name not in table:
                if partial:
                    continue
                if key.required:
                    raise VideoTrackError(f"missing (required): {key.doc}", file=file, field=name)
                out[key.name] = key.default
                continue
            out[key.name] = _check_key(key, table[key.name], name, file, base)
        return out


@dataclass(frozen=True)
class Variants:
    """Tables whose ``tag`` key selects their schema, e.g. filter steps selected by ``type``."""

    name: str
    tag: str
    sections: Mapping[str, Section]
    doc: str = ""

    def validate(self, table, *, where=None, file=None, base=None) -> dict:
        where = self.name if where is None else where
        if not isinstance(table, Mapping):
            raise VideoTrackError(f"must be a table, got {_kind(table)}", file=file, field=where)
        if self.tag not in table:
            raise VideoTrackError(
                f"missing {self.tag!r}; one of: {', '.join(self.sections)}", file=file, field=where
            )
        kind = table[self.tag]
        if kind not in self.sections:
            raise VideoTrackError(
                f"unknown {self.tag} {kind!r}; one of: {', '.join(self.sections)}",
                file=file,
                field=f"{where}.{self.tag}",
            )
        rest = {k: v for k, v in table.items() if k != self.tag}
        return {self.tag: kind, **self.sections[kind].validate(rest, where=where, file=file,
                                                                base=base)}


#: Registered top-level sections, in documentation order.
SECTIONS: dict[str, Section] = {}


def register_section(section: Section) -> Section:
    """Add a top-level section (once per name) and return it."""
    if section.name in SECTIONS and SECTIONS[section.name] != section:
        raise ValueError(f"config section {section.name!r} is registered twice")
    SECTIONS[section.name] = section
    return section


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
        return tomllib.loads(text)
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


def describe_section(section: Section | Variants, level: int = 3) -> str:
    """Markdown reference of a section: one table row per key (generated docs)."""
    if isinstance(section, Variants):
        parts = [f"{section.doc}\n"] if section.doc else []
        for kind, sub in section.sections.items():
            parts.append(f"{'#' * level} `{section.tag} = \"{kind}\"`\n\n{sub.doc}\n")
            if sub.keys:
                parts.append(_key_table(sub))
        return "\n".join(parts)
    head = f"[[{section.name}]]" if section.array else f"[{section.name}]"
    return f"{'#' * level} `{head}`\n\n{section.doc}\n\n{_key_table(section)}"


def _key_table(section: Section) -> str:
    rows = ["| key | type | default | meaning |", "| --- | --- | --- | --- |"]
    for key in section.keys:
        default = "required" if key.required else f"`{_toml(key.default)}`"
        extra = f" One of: {', '.join(_toml(c) for c in key.choices)}." if key.choices else ""
        cells = (f"`{key.name}`", key.type, default, key.doc + extra)
        rows.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(rows) + "\n"


def _toml(value) -> str:
    """A default or choice as it is written in TOML."""
    return json.dumps(value) if isinstance(value, bool | str | list) else repr(value)


# -- sections derived from settings records -----------------------------------------------------

_RECORD_TYPES = {int: "int", float: "float", bool: "bool", str: "str"}


class RecordKey(NamedTuple):
    """A key derived from a field of a settings record: the :class:`Key`, the field names
    from the record down to the field (``("error", "mode")``), and the value that stands for
    None (``none`` metadata; None when the field cannot be None)."""

    key: Key
    path: tuple[str, ...]
    none: Any = None


def record_keys(record: type, default=None) -> list[RecordKey]:
    """The keys of a section derived from the fields of a frozen dataclass ``record``.

    Each field becomes a key of the same name with its type (int, float, bool or str; an
    ``X | None`` field is written as its ``none`` metadata value in the file), its default (from
    ``default``, an instance, or ``record()``) and its metadata ``doc``, ``min``, ``max`` and
    ``choices``. A field that is itself a record contributes its own fields as keys when its
    metadata has ``flatten`` (a mapping renaming some of them). See :mod:`kinematics.settings`.
    """
    default = record() if default is None else default
    hints = typing.get_type_hints(record)
    out: list[RecordKey] = []
    for f in dataclasses.fields(record):
        meta, type_, value = f.metadata, hints[f.name], getattr(default, f.name)
        where = f"{record.__name__}.{f.name}"
        if dataclasses.is_dataclass(type_):
            if "flatten" not in meta:
                raise TypeError(f"{where}: a nested record needs metadata 'flatten'")
            rename = meta["flatten"]
            out += [RecordKey(dataclasses.replace(k.key, name=rename.get(k.key.name,
                                                                          k.key.name)),
                              (f.name, *k.path), k.none) for k in record_keys(type_, value)]
            continue
        none = None
        args = typing.get_args(type_)
        if typing.get_origin(type_) in (types.UnionType, typing.Union) and type(None) in args:
            if "none" not in meta:
                raise TypeError(f"{where} may be None: give it metadata 'none', the value a "
                                "project file writes for None")
            none = meta["none"]
            (type_,) = (a for a in args if a is not type(None))
            value = none if value is None else value
        if type_ not in _RECORD_TYPES:
            raise TypeError(f"{where}: type {type_!r} has no project-file form")
        key = Key(f.name, _RECORD_TYPES[type_], value, meta.get("doc", ""),
                  choices=tuple(meta["choices"]) if "choices" in meta else None,
                  min=meta.get("min"), max=meta.get("max"))
        out.append(RecordKey(key, (f.name,), none))
    names = [k.key.name for k in out]
    if len(set(names)) != len(names):
        raise TypeError(f"{record.__name__}: two fields give the same key in {names}")
    return out


def record_section(name: str, record: type, doc: str = "") -> Section:
    """A :class:`Section` with one key per field of ``record`` (:func:`record_keys`)."""
    return Section(name, tuple(k.key for k in record_keys(record)), doc)


def record_from_table(record: type, table: Mapping, *, file=None, where: str = ""):
    """The ``record`` of a checked section (:func:`record_section`): each key's value goes
    to its field (a ``none`` value becomes None); keys not in ``table`` keep the record's
    default. The record's own validation errors are re-raised as :class:`VideoTrackError`
    naming the file and ``where.key``."""
    kwargs: dict = {}
    by_field = {}
    for k in record_keys(record):
        by_field[".".join(k.path)] = k.key.name
        if k.key.name not in table:
            continue
        value = table[k.key.name]
        if k.none is not None and value == k.none:
            value = None
        target = kwargs
        for part in k.path[:-1]:
            target = target.setdefault(part, {})
        target[k.path[-1]] = value
    try:
        return _build_record(record, kwargs)
    except LocatedError as err:
        name = by_field.get(err.field, err.field)
        raise VideoTrackError(err.message, file=file,
                              field=".".join(p for p in (where, name) if p) or None) from None


def _build_record(record: type, kwargs: Mapping):
    hints = typing.get_type_hints(record)
    return record(**{name: _build_record(hints[name], value)
                     if dataclasses.is_dataclass(hints[name]) else value
                     for name, value in kwargs.items()})


# -- value checking -----------------------------------------------------------------------------


def _kind(value) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, Mapping):
        return "a table"
    return type(value).__name__


def _split_union(type_: str) -> list[str]:
    parts, depth, cur = [], 0, ""
    for ch in type_:
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
        if ch == "|" and depth == 0:
            parts.append(cur.strip())
            cur = ""
        else:
            cur += ch
    parts.append(cur.strip())
    return parts


def _convert(type_: str, value, key: Key, name: str, file, base):
    """Value converted to ``type_`` or raise VideoTrackError; unions try each alternative."""
    alternatives = _split_union(type_)
    if len(alternatives) > 1:
        errors = []
        for alt in alternatives:
            try:
                return _convert(alt, value, key, name, file, base)
            except VideoTrackError as err:
                errors.append(err)
        # Prefer the message of the alternative whose outer type matched.
        for err in errors:
            if not err.message.startswith("must be "):
                raise err
        raise VideoTrackError(
            f"must be {' or '.join(_article(a) for a in alternatives)}, got {_kind(value)}",
            file=file,
            field=name,
        )
    if type_.startswith("list[") and type_.endswith("]"):
        if not isinstance(value, list):
            raise VideoTrackError(f"must be {_article(type_)}, got {_kind(value)}",
                                  file=file, field=name)
        inner = type_[5:-1]
        return [_convert(inner, v, key, f"{name}[{i}]", file, base) for i, v in enumerate(value)]
    ok = {
        "str": isinstance(value, str),
        "path": isinstance(value, str | os.PathLike),
        "bool": isinstance(value, bool),
        "int": isinstance(value, int) and not isinstance(value, bool),
        "float": isinstance(value, int | float) and not isinstance(value, bool),
        "table": isinstance(value, Mapping),
    }
    if type_ not in ok:
        raise ValueError(f"unknown schema type {type_!r} of {name}")
    if not ok[type_]:
        raise VideoTrackError(f"must be {_article(type_)}, got {_kind(value)}", file=file,
                              field=name)
    if type_ == "float":
        value = float(value)
        if value != value or value in (float("inf"), float("-inf")):
            raise VideoTrackError("must be a finite number", file=file, field=name)
    if type_ in ("int", "float"):
        if key.min is not None and value < key.min:
            raise VideoTrackError(f"must be at least {key.min:g}, got {value:g}", file=file,
                                  field=name)
        if key.max is not None and value > key.max:
            raise VideoTrackError(f"must be at most {key.max:g}, got {value:g}", file=file,
                                  field=name)
    if type_ == "path":
        if not value:
            return ""  # an empty path means "not given"
        p = Path(value).expanduser()  # also accepts an already resolved path
        return (Path(base) / p if base is not None and not p.is_absolute() else p).absolute()
    if type_ == "table" and key.items is not None:
        return key.items.validate(value, where=name, file=file, base=base)
    return value


_NAMES = {
    "str": ("a string", "strings"),
    "path": ("a path (string)", "paths"),
    "bool": ("true or false", "booleans"),
    "int": ("an integer", "integers"),
    "float": ("a number", "numbers"),
    "table": ("a table", "tables"),
}


def _article(type_: str, plural: bool = False) -> str:
    if type_.startswith("list["):
        return ("lists" if plural else "a list") + f" of {_article(type_[5:-1], plural=True)}"
    return _NAMES[type_][plural] if type_ in _NAMES else type_


def _check_key(key: Key, value, name: str, file, base):
    out = _convert(key.type, value, key, name, file, base)
    if key.choices is not None and out not in key.choices:
        raise VideoTrackError(
            f"must be one of {', '.join(map(repr, key.choices))}, got {out!r}",
            file=file,
            field=name,
        )
    if key.length is not None and isinstance(out, list) and len(out) != key.length:
        raise VideoTrackError(f"must have {key.length} entries, got {len(out)}", file=file,
                              field=name)
    if key.check is not None:
        problem = key.check(out)
        if problem:
            raise VideoTrackError(problem, file=file, field=name)
    return out


# -- the sections of marker detection -----------------------------------------------------------


def _frames_rule(text: str) -> str | None:
    from videotrack.video import parse_frame_range

    try:
        parse_frame_range(text)
    except ValueError as err:
        return str(err)
    return None


def _odd(value: int) -> str | None:
    return None if value % 2 == 1 else f"must be odd (a kernel has a centre pixel), got {value}"


def _roi_rule(roi: list) -> str | None:
    if roi and len(roi) != 4:
        return f"must be [x, y, width, height], got {len(roi)} entries"
    if roi and (roi[2] < 1 or roi[3] < 1):
        return f"width and height must be at least 1, got {roi[2]} x {roi[3]}"
    return None


def _view_hsv_rule(hsv: list) -> str | None:
    if not hsv:
        return None
    if len(hsv) != 3:
        return f"must be [hue, saturation, value], got {len(hsv)} entries"
    return _hsv_rule(hsv)


def _hsv_rule(hsv: list) -> str | None:
    if hsv[0] > 179:
        return f"OpenCV hue runs 0..179, got {hsv[0]}"
    return None


def _rects_rule(rects: list) -> str | None:
    for i, r in enumerate(rects):
        if len(r) != 4 or r[2] < 1 or r[3] < 1:
            return f"entry {i} must be [x, y, width, height] with a positive size, got {r}"
    return None


def _polygons_rule(polygons: list) -> str | None:
    for i, poly in enumerate(polygons):
        if len(poly) < 3 or any(len(p) != 2 for p in poly):
            return f"polygon {i} must have at least 3 [x, y] points"
    return None


VIDEO = register_section(Section("video", (
    Key("path", "path | list[path]", doc="Video file or image-sequence folder; a list of them "
        "for synchronised cameras (one file per camera). Not needed when [keypoints] files is "
        "set."),
    Key("fps", "float", 0.0, "Frame rate; 0 takes it from the video (image sequences: 25).",
        min=0.0, max=1e6),
    Key("deinterlace", "str", "none", "Split each frame into its two fields (half-frames).",
        choices=("none", "fields")),
    Key("field_order", "str", "top", "Which field was exposed first: 'top' (even rows) or "
        "'bottom' (odd rows; PAL DV).", choices=("top", "bottom")),
    Key("line_doubling", "str", "none", "Stretch half-frames back to full height: 'repeat' "
        "rows or 'linear' interpolation.", choices=("none", "repeat", "linear")),
    Key("frames", "str", "", "Frame range 'A:B' (start included, stop excluded, 0-based); "
        "empty for all.", check=_frames_rule),
), doc="The video(s) to read and how to split frames in time."))

VIEWS = register_section(Section("views", (
    Key("name", "str", doc="Name of the view, unique."),
    Key("roi", "list[int]", [], "Rectangle [x, y, width, height] of the frame holding the view; "
        "empty for the whole frame.", min=0, check=_roi_rule),
    Key("flip_x", "bool", False, "Mirror the view left-right (a mirror set-up)."),
    Key("flip_y", "bool", False, "Mirror the view top-bottom."),
    Key("camera", "str", "", "Camera of this view in the camera file; empty: the view's name."),
    Key("video", "int", 0, "Index of the view's video in video.path (synchronised cameras).",
        min=0),
    Key("model_markers", "list[str]", [], "The chain's markers this view shows (names, or "
        "patterns such as 'LF_*'); the fit matches the view's detections to these only. "
        "Empty: all. For markers of several colours: one view per colour on the same "
        "camera, each with its colour's markers and hsv_lower/hsv_upper."),
    Key("hsv_lower", "list[int]", [], "This view keeps only markers of this colour: lowest "
        "[hue, saturation, value], in place of the filter chain's hsv_range step (which the "
        "chain must have). Empty: the chain's own range.", min=0, max=255,
        check=_view_hsv_rule),
    Key("hsv_upper", "list[int]", [], "Highest [hue, saturation, value] of this view's "
        "colour (with hsv_lower).", min=0, max=255, check=_view_hsv_rule),
), doc="One entry per view: a rectangle of a video frame seen by one camera.", array=True))

_MORPH_KEYS = (
    Key("size", "int", 3, "Kernel size in pixels (odd).", min=1, max=99, check=_odd),
    Key("iterations", "int", 1, "How often the operation is repeated.", min=1, max=100),
    Key("shape", "str", "ellipse", "Kernel shape.", choices=("ellipse", "rect", "cross")),
)

FILTER_STEPS = Variants("filters.steps", "type", {
    "channel": Section("channel", (
        Key("channel", "str", doc="Colour channel to keep as the grey image.",
            choices=("blue", "green", "red")),
    ), doc="Colour → grey: keep one colour channel."),
    "grey": Section("grey", (), doc="Colour → grey: luminance (OpenCV's BGR2GRAY)."),
    "hsv_range": Section("hsv_range", (
        Key("lower", "list[int]", doc="Lowest [hue, saturation, value]; hue 0..179.",
            length=3, min=0, max=255, check=_hsv_rule),
        Key("upper", "list[int]", doc="Highest [hue, saturation, value]. A lower hue above the "
            "upper hue wraps around red.", length=3, min=0, max=255, check=_hsv_rule),
    ), doc="Colour → mask: pixels whose HSV colour lies in the range."),
    "background": Section("background", (
        Key("frames", "int", 25, "Frames sampled evenly over the whole video for the median.",
            min=3, max=500),
        Key("polarity", "str", "brighter", "Keep what is brighter than the background, darker, "
            "or both (absolute difference).", choices=("brighter", "darker", "both")),
    ), doc="Grey → grey: subtract the per-pixel median of sampled frames (computed once)."),
    "invert": Section("invert", (), doc="Grey or mask: 255 - value (dark markers become bright)."),
    "threshold": Section("threshold", (
        Key("value", "int", doc="Pixels brighter than this grey level become marker pixels.",
            min=0, max=254),
    ), doc="Grey → mask: global threshold."),
    "otsu": Section("otsu", (), doc="Grey → mask: threshold chosen per image by Otsu's method."),
    "adaptive": Section("adaptive", (
        Key("block_size", "int", 15, "Side of the neighbourhood in pixels (odd).", min=3,
            max=255, check=_odd),
        Key("offset", "float", 10.0, "A pixel is a marker pixel when it exceeds its "
            "neighbourhood's mean by more than this.", min=-255.0, max=255.0),
        Key("method", "str", "mean", "Neighbourhood mean: plain or Gaussian-weighted.",
            choices=("mean", "gaussian")),
    ), doc="Grey → mask: threshold relative to the local mean."),
    "erode": Section("erode", _MORPH_KEYS, doc="Shrink bright regions (grey or mask)."),
    "dilate": Section("dilate", _MORPH_KEYS, doc="Grow bright regions (grey or mask)."),
    "open": Section("open", _MORPH_KEYS, doc="Erode then dilate: removes specks."),
    "close": Section("close", _MORPH_KEYS, doc="Dilate then erode: fills small holes."),
    "mask": Section("mask", (
        Key("rects", "list[list[int]]", [], "Rectangles [x, y, width, height] in view "
            "coordinates.", min=0, check=_rects_rule),
        Key("polygons", "list[list[list[float]]]", [], "Polygons [[x, y], ...] in view "
            "coordinates.", check=_polygons_rule),
        Key("image", "path", "", "Image of the view's size; non-zero pixels are masked."),
        Key("keep", "bool", False, "true: keep only the masked area, discard the rest."),
        Key("view", "str", "", "Apply to this view only; empty: every view."),
    ), doc="Any → same: zero the masked area (static reflections, the frame of a mirror)."),
}, doc="Filter steps run in order on each view image; the chain must end with a mask.")

FILTERS = register_section(Section("filters", (
    Key("steps", "list[table]", doc="Ordered filter steps ([[filters.steps]] tables); not "
        "needed when [keypoints] files is set.",
        items=FILTER_STEPS),
), doc="The filter chain that turns a view image into a mask of marker pixels."))

MARKERS = register_section(Section("markers", (
    Key("min_area", "int", 1, "Smallest marker region in pixels.", min=1, max=10**7),
    Key("max_area", "int", 10000, "Largest marker region in pixels.", min=1, max=10**8),
    Key("max_aspect", "float", 0.0, "Largest ratio of a region's long to short axis (second "
        "moments); 0 turns the gate off.", min=0.0, max=1000.0,
        check=lambda v: None if v == 0 or v >= 1 else f"must be 0 (off) or at least 1, got {v}"),
    Key("min_circularity", "float", 0.0, "Smallest circularity area/(2π·(λ1+λ2)) (1 for a "
        "disc, lower for elongated or ragged regions); 0 turns the gate off.", min=0.0,
        max=1.0),
    Key("weighting", "str", "intensity", "Centroid of the pixel intensities (sub-pixel) or of "
        "the region's pixels ('binary').", choices=("intensity", "binary")),
    Key("window_pad", "int", 1, "Pixels added around a region for the intensity-weighted "
        "centroid and its local background.", min=0, max=20),
    Key("connectivity", "int", 8, "Pixel neighbourhood of a region.", choices=(4, 8)),
), doc="Which regions of the mask are markers, and how their centroids are measured."))

OUTPUT = register_section(Section("output", (
    Key("detections", "path", "", "Detections file; empty: '<first video>.detections.npz' "
        "beside the config file."),
), doc="Where results go."))


# -- model and fitting ----------------------------------------------------------------------

CHAIN = register_section(Section("chain", (
    Key("path", "path", "", "Chain XML file (joints, axes, segments, markers)."),
    Key("histograms", "path", "", "Histogram archive XML applied on top of the chain's own "
        "histograms (e.g. learned in an earlier experiment); empty for none."),
), doc="The kinematic model fitted to the detections."))

CAMERAS = register_section(Section("cameras", (
    Key("path", "path", "", "Camera TOML file; every view's camera must be in it."),
), doc="Where the cameras of the views are described."))

# Every field of AnnealParams (and of its ErrorOptions, flattened: ``error`` is the mode) is a
# key, with the type, default, bounds and doc declared in kinematics/settings.py.
_ANNEAL_DOC = ("Simulated annealing (Eq. 6), the error function (Eq. 5 or a variant) and the "
               "choice among candidate postures; defaults are the best measured settings, "
               "profile = \"paper\" gives the paper's (Table 1, Eq. 5).")
ANNEAL = register_section(Section("anneal", (
    Key("profile", "str", "best", "Settings every other key of this section starts from: "
        "'best' (the best measured, the defaults listed here) or 'paper' (the paper's Table 1 "
        "and Eq. 5, no refinement, one answer per frame: reproduces Table 2). Keys you set "
        "yourself override the profile.", choices=PROFILES),
    *record_section("anneal", AnnealParams).keys), _ANNEAL_DOC))


def anneal_from_table(table: Mapping, given=None, *, file=None) -> AnnealParams:
    """The :class:`AnnealParams` of a checked ``[anneal]`` table: its profile's settings,
    with the keys the file sets (``given``; default every key) on top."""
    profile = table.get("profile", "best")
    base = {k.key.name: k.key.default for k in record_keys(AnnealParams,
                                                           AnnealParams.profile(profile))}
    given = set(table if given is None else given)
    values = {name: (table[name] if name in given else default)
              for name, default in base.items()}
    return record_from_table(AnnealParams, values, file=file, where="anneal")

FIT = register_section(Section("fit", (
    Key("results", "path", "", "Results CSV; empty: '<detections>.results.csv' beside the "
        "detections file."),
    Key("plot", "bool", False, "Also write a PNG of the angle time courses with bad frames "
        "marked (beside the results)."),
    Key("jobs", "int", 0, "Threads for fitting; 0 uses every core.", min=0, max=1024),
), doc="Outputs of 'videotrack fit' and 'videotrack run'."))


# -- the markerless route -------------------------------------------------------------------

def _pairs_rule(offsets: list) -> str | None:
    for i, pair in enumerate(offsets):
        if len(pair) != 2:
            return f"entry {i} must be [x, y], got {pair}"
    return None


def _names_rule(table: Mapping) -> str | None:
    for kp, marker in table.items():
        if not isinstance(marker, str) or not marker:
            return f"{kp}: must name a chain marker (a string), got {marker!r}"
    return None


def _keypoint_filter_section() -> Section:
    from videotrack.keypoint_filters import KeypointFilterSettings

    return record_section("keypoints.filter", KeypointFilterSettings,
                          "Anipose's 2D filters, each off by default (docs/markerless.md).")


KEYPOINTS = register_section(Section("keypoints", (
    Key("files", "list[path]", [], "2D keypoint files (or OpenPose JSON folders), one per "
        "camera: per view in the order of [[views]], else per camera in the camera file's "
        "order. Empty: the marker route (detect markers in the video)."),
    Key("format", "str", "", "Keypoint file format; empty: detected from each file.",
        choices=("", "dlc", "sleap", "openpose", "lightning-pose", "anipose")),
    Key("individual", "str", "", "The animal, track or person to follow: a name or an index; "
        "empty: the first (OpenPose: the largest person)."),
    Key("model", "str", "", "OpenPose keypoint names: BODY_25, BODY_25B or COCO; empty: "
        "from the number of points."),
    Key("crop_offsets", "list[list[float]]", [], "Per file, [x, y] pixels added to its "
        "keypoints (the tracker ran on a crop); empty: none.", check=_pairs_rule),
    Key("frame_offsets", "list[int]", [], "Per file, added to its frame numbers (the tracked "
        "video started later); empty: none."),
    Key("markers", "table", {}, "Keypoint name = chain marker name; empty: keypoints map to "
        "the markers named like them. Keypoints without a marker are left out.",
        check=_names_rule),
    Key("route", "str", "2d", "'2d': fit the chain to the 2D keypoints (labelled "
        "reprojection error); '3d': triangulate them first and fit the chain to the 3D "
        "points (set [anneal] tau0 and reanalysis_threshold in length units).",
        choices=("2d", "3d")),
    Key("triangulation", "str", "linear", "Route '3d': the triangulation backend.",
        choices=("linear", "ransac", "optim")),
    Key("min_score", "float", 0.0, "Keypoints scored below this are not used (after the "
        "filters).", min=0.0, max=1.0),
    Key("filter", "table", {}, "[keypoints.filter]: the 2D filters (keys below).",
        items=_keypoint_filter_section()),
), doc="The markerless route: fit the chain to 2D keypoints (DeepLabCut, SLEAP, OpenPose, "
       "Lightning Pose, Anipose) instead of detected markers; [video] and [filters] are then "
       "not needed."))
