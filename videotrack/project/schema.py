"""The schema mechanism of project files: how a section's keys are declared, checked and
documented.

A section is a :class:`Section` of :class:`Key` entries (name, type, default, bounds, choices,
doc, an extra ``check``); :meth:`Section.validate` checks a TOML table against it and
:func:`describe_section` turns it into a Markdown reference. :class:`Variants` is a table whose
tag key selects its section (filter steps by ``type``).

A section can be derived from a frozen settings record whose fields carry their metadata
(:func:`kinematics.fit.settings.setting`): :func:`record_section` makes one :class:`Key` per field
(:func:`record_keys`), and :func:`record_from_table` builds the record back from the checked
table, re-raising the record's own validation errors against the file and key.

The sections a project file may hold are registered in :data:`SECTIONS` with
:func:`register_section` (:mod:`videotrack.project.sections` and the modules that own one);
:mod:`videotrack.project.config` reads, merges and checks files against them.

Type strings
    ``str``, ``int``, ``float`` (an integer is accepted), ``bool``, ``path`` (a string, resolved
    against the config file's folder), ``table`` (a TOML table), ``list[T]`` for any type T, and
    unions ``A | B``.

Errors name the file and the dotted key: ``run.toml: filters.steps[2].value: must be at most
255, got 300``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from kinematics.errors import LocatedError
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
        if not isinstance(kind, str) or kind not in self.sections:
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
    metadata has ``flatten`` (a mapping renaming some of them). See :mod:`kinematics.fit.settings`.
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
