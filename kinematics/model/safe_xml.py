"""Hardened XML reading for chain files and histogram archives; the only module that imports lxml.

Chain files travel between labs, so a file is treated as untrusted input. The parser never
resolves entities, never loads a DTD and never touches the network or any file besides the
one it reads: any document with a ``<!DOCTYPE`` is refused outright (the format needs none),
which also disposes of XXE and billion-laughs documents. Size, nesting depth and element
count are limited, and the depth/count limits are checked while streaming, so an absurd
document is refused before it is built. Every problem becomes one
:class:`~kinematics.errors.KinematicsError` naming the file and, where known, the line — never
the raw libxml2 dump.

After parsing, a document is validated against the XSD shipped in ``kinematics/model/schema`` (which
also fills in attribute defaults); the typed attribute readers below then refuse what the
schema's ``xs:double`` lets through (``NaN``, ``INF``, overflowing ``1e400``).
"""

from __future__ import annotations

import functools
import importlib.resources
import math
import os
import re
import threading

from lxml import etree

from kinematics.errors import KinematicsError

MAX_BYTES = 20 * 1024 * 1024
#: Joints a chain may nest, from its root joint to a tip (a 60-vertebra spine needs 60).
MAX_JOINT_DEPTH = 120
#: XML nesting that allows: a joint ``d`` levels down sits at element level ``2·d + 1``
#: (``<body>``, ``<chain>``, then joint/segment pairs) and its markers at ``2·d + 3``. It stays
#: below libxml2's own limit of 256 levels (lifting that would need its ``huge_tree`` mode).
MAX_DEPTH = 2 * MAX_JOINT_DEPTH + 3
MAX_ELEMENTS = 200_000

_PARSER_OPTIONS = dict(
    resolve_entities=False,
    no_network=True,
    load_dtd=False,
    dtd_validation=False,
    huge_tree=False,
    remove_comments=False,
)
_CHUNK = 64 * 1024

Element = etree._Element  # re-exported for type hints of the XML modules


# -- reading --------------------------------------------------------------------------------
def read_document(
    path: str | os.PathLike,
    root: str,
    *,
    max_bytes: int = MAX_BYTES,
    max_depth: int = MAX_DEPTH,
    max_elements: int = MAX_ELEMENTS,
) -> Element:
    """Read, parse and schema-validate the file at ``path`` whose root element must be ``root``.

    The file size is checked before anything is read. Errors carry ``file=path``.
    """
    source = os.fspath(path)
    data = _read_bytes(source, max_bytes)
    return parse_document(
        data, source, root,
        max_bytes=max_bytes, max_depth=max_depth, max_elements=max_elements,
    )


def read_foreign(
    path: str | os.PathLike,
    *,
    max_bytes: int = MAX_BYTES,
    max_depth: int = MAX_DEPTH,
    max_elements: int = MAX_ELEMENTS,
) -> Element:
    """Read and parse another tool's XML file (e.g. a Qualisys ``.qca``): the same limits and
    refusals as :func:`read_document` (size, depth, element count, no DTD or entities), but no
    schema; the caller checks the elements it needs. Errors carry ``file=path``."""
    source = os.fspath(path)
    data = _read_bytes(source, max_bytes)
    try:
        if len(data) > max_bytes:
            raise KinematicsError(_too_large(len(data), max_bytes))
        if not data.strip():
            raise KinematicsError("file is empty")
        _refuse_doctype_bytes(data)
        return _parse_streaming(data, max_depth, max_elements)
    except KinematicsError as err:
        raise err.located(file=source) from None


def parse_document(
    data: bytes | str,
    source: str,
    root: str,
    *,
    max_bytes: int = MAX_BYTES,
    max_depth: int = MAX_DEPTH,
    max_elements: int = MAX_ELEMENTS,
) -> Element:
    """Parse ``data`` (bytes, or text that is encoded as UTF-8) named ``source`` in errors,
    check that its root element is ``root``, and validate it against the package schema.

    Returns the root element; its ``sourceline`` and those of its descendants are valid.
    """
    try:
        if isinstance(data, str):
            # lxml refuses str input with an encoding declaration; bytes work for both.
            data = data.encode("utf-8")
        if len(data) > max_bytes:
            raise KinematicsError(_too_large(len(data), max_bytes))
        if not data.strip():
            raise KinematicsError("file is empty")
        _refuse_doctype_bytes(data)
        elem = _parse_streaming(data, max_depth, max_elements, root)
        if elem.tag != root:
            raise KinematicsError(
                f"root element is <{elem.tag}>, expected <{root}>", line=elem.sourceline
            )
        validate(elem)
    except UnicodeEncodeError:
        raise KinematicsError("text is not valid Unicode", file=source) from None
    except KinematicsError as err:
        raise err.located(file=source) from None
    return elem


def _read_bytes(source: str, max_bytes: int) -> bytes:
    """The file's bytes, its size checked before anything is read."""
    try:
        size = os.stat(source).st_size
        if size > max_bytes:
            raise KinematicsError(_too_large(size, max_bytes), file=source)
        with open(source, "rb") as f:
            return f.read(max_bytes + 1)  # the file may have grown since stat
    except OSError as err:
        raise KinematicsError(f"cannot read file: {err.strerror or err}", file=source) from None


def _too_large(size: int, limit: int) -> str:
    return f"file is too large ({size:,} bytes; the limit is {limit:,} bytes)"


_DOCTYPE_MESSAGE = "documents with a <!DOCTYPE> are refused (DTDs and entities are not supported)"


def _refuse_doctype_bytes(data: bytes) -> None:
    """Fast pre-check for the usual 8-bit encodings; the parse re-checks for all others."""
    at = data.find(b"<!DOCTYPE")
    if at >= 0:
        raise KinematicsError(_DOCTYPE_MESSAGE, line=data.count(b"\n", 0, at) + 1)


def _parse_streaming(data: bytes, max_depth: int, max_elements: int, root: str = "") -> Element:
    """Parse with the hardened options, refusing deep or huge documents while streaming."""
    parser = etree.XMLPullParser(events=("start", "end"), **_PARSER_OPTIONS)
    depth = count = 0
    try:
        for at in range(0, len(data), _CHUNK):
            parser.feed(data[at:at + _CHUNK])
            for event, elem in parser.read_events():
                if event == "end":
                    depth -= 1
                    continue
                if count == 0 and elem.getroottree().docinfo.doctype:
                    raise KinematicsError(_DOCTYPE_MESSAGE)
                depth += 1
                count += 1
                if depth > max_depth:
                    raise KinematicsError(_too_deep(max_depth, elem), line=elem.sourceline)
                if count > max_elements:
                    raise KinematicsError(
                        f"too many elements (more than {max_elements})", line=elem.sourceline
                    )
        return parser.close()
    except etree.XMLSyntaxError as err:
        raise _syntax_error(data, err, max_depth, root) from None


def _too_deep(max_depth: int, elem: Element | None = None, root: str = "") -> str:
    """The message for a document nested deeper than ``max_depth``, in joints for chains."""
    joints = (max_depth - 3) // 2
    if elem is not None:
        in_chain = any(True for _ in elem.iterancestors("chain"))
    else:
        in_chain = root == "body"
    if in_chain:
        where = ""
        if elem is not None:
            n = sum(1 for _ in elem.iterancestors("joint")) + (elem.tag == "joint")
            where = f" (this line is {n} joints down)"
        return (f"chain is nested too deeply: a chain may nest at most {joints} joints from "
                f"its root joint to a tip{where}; XML nesting is limited to {max_depth} "
                "levels")
    return f"elements are nested too deeply (more than {max_depth} levels)"


def _syntax_error(data: bytes, err: etree.XMLSyntaxError, max_depth: int,
                  root: str = "") -> KinematicsError:
    # The pull parser sometimes reports a follow-up error ("no element found"); a plain parse
    # of the same (size-limited) bytes names the first problem.
    try:
        etree.fromstring(data, etree.XMLParser(**_PARSER_OPTIONS))
    except etree.XMLSyntaxError as first:
        err = first
    # libxml2 may quote the document on further lines; keep the first.
    msg = re.sub(r", line \d+, column \d+$", "", (err.msg or str(err)).strip().split("\n")[0])
    line = err.lineno or None
    m = re.match(r"Premature end of data in tag (\S+) line (\d+)", msg)
    if m:
        msg = f"file ends before <{m[1]}> (opened on line {m[2]}) is closed; truncated file?"
    elif msg.startswith("Document is empty"):
        msg = "file holds no XML element"
    elif msg.startswith("Excessive depth"):  # libxml2's own limit, hit within one chunk
        msg = _too_deep(max_depth, root=root)
    elif line is not None and line >= data.count(b"\n") + 1 and data.rfind(b"<") > data.rfind(
            b">"):  # an unclosed tag at the very end
        msg = "file ends in the middle of a tag; truncated file?"
    else:
        msg = "malformed XML: " + msg[:1].lower() + msg[1:]
    return KinematicsError(msg.strip(), line=line)


# -- schema validation ----------------------------------------------------------------------
_SCHEMA_LOCK = threading.Lock()


@functools.cache
def _schema() -> etree.XMLSchema:
    ref = importlib.resources.files("kinematics.model") / "schema" / "chain.xsd"
    doc = etree.fromstring(ref.read_bytes(), etree.XMLParser(**_PARSER_OPTIONS))
    # attribute_defaults: the defaults declared in the XSD are the only copy of them.
    return etree.XMLSchema(doc, attribute_defaults=True)


def validate(elem: Element) -> None:
    """Validate a parsed document against ``chain.xsd`` (filling in attribute defaults);
    raise :class:`KinematicsError` with the line and element of the first problem."""
    with _SCHEMA_LOCK:  # one schema object, built once and shared; libxml2 is not re-entrant
        schema = _schema()
        if schema.validate(elem):
            return
        first = schema.error_log[0]
    m = re.match(r"Element '([^']+)'(?:, attribute '([^']+)')?: (.*)", first.message, re.S)
    if not m:
        raise KinematicsError(_simplify(first.message), line=first.line or None)
    tag, attr, msg = m.groups()
    msg = _simplify(msg)
    if attr and f"'{attr}'" not in msg:
        msg = f"attribute '{attr}': {msg}"
    try:
        found = elem.getroottree().xpath(first.path) if first.path else []
    except etree.XPathError:
        found = []
    where = describe(found[0]) if found else f"<{tag}>"
    raise KinematicsError(msg, line=first.line or None, field=where)


def describe(elem: Element) -> str:
    """How errors name an element: ``<axis name="phi">``, or ``<run>`` without a name."""
    name = elem.get("name")
    return f"<{elem.tag}>" if name is None else f'<{elem.tag} name="{_one_line(name)}">'


def _one_line(text: str) -> str:
    """Escape line breaks (attribute values may hold them as ``&#10;``): errors are one line."""
    return text.replace("\n", "\\n").replace("\r", "\\r")


_PATTERN_HELP = {
    r"[^\s.]+": "is not a valid name (non-empty, without spaces or '.')",
    r"\S+( \S+)*": "is not a valid name (non-empty, without leading or double spaces)",
}

_TYPE_HELP = {
    "xs:double": "a number",
    "xs:positiveInteger": "a whole number >= 1",
    "binCount": "a whole number from 1 to 36000",
}


def _simplify(msg: str) -> str:
    """Shorten the body of a libxml2 schema message, keeping what went wrong."""
    msg = _one_line(msg.strip().rstrip("."))
    msg = re.sub(r"\[facet '\w+'\] ", "", msg)
    msg = re.sub(
        r"'(.*)' is not a valid value of the (?:atomic|list) type '([^']+)'",
        lambda m: f"'{m[1]}' is not {_TYPE_HELP.get(m[2], 'a valid ' + m[2])}", msg)
    msg = re.sub(r"The value '(.*)' is not an element of the set \{(.*)\}",
                 r"'\1' is not one of \2", msg)
    msg = re.sub(r"The value '(.*)' has a length of '(\d+)'; this differs from the allowed "
                 r"length of '(\d+)'", r"'\1' has \2 numbers, needs \3", msg)
    msg = re.sub(r"The value '(.*)' is not accepted by the pattern '(.*)'",
                 lambda m: f"'{m[1]}' {_PATTERN_HELP.get(m[2], 'does not match ' + m[2])}", msg)
    msg = re.sub(r"The value '(.*)' is (greater|less) than the (?:maximum|minimum) value "
                 r"allowed \('(.*)'\)", r"'\1' is \2 than \3", msg)
    msg = re.sub(r"This element is not expected\. Expected is(?: one of)? \( (.*) \)",
                 r"element not allowed here (expected: \1)", msg)
    msg = msg.replace("This element is not expected", "element not allowed here")
    msg = re.sub(r"Missing child element\(s\)\. Expected is(?: one of)? \( (.*) \)",
                 r"missing child element (expected: \1)", msg)
    msg = re.sub(r"The attribute '(.*)' is required but missing", r"attribute '\1' is missing",
                 msg)
    msg = re.sub(r"The attribute '(.*)' is not allowed", r"attribute '\1' is not allowed", msg)
    msg = msg.replace("Character content other than whitespace is not allowed because the "
                      "content type is 'element-only'", "text is not allowed here")
    return msg


# -- typed attributes -----------------------------------------------------------------------
def _number(text: str, attr: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise KinematicsError(f"attribute '{attr}': '{text}' is not a number") from None
    if not math.isfinite(value):
        raise KinematicsError(f"attribute '{attr}': '{text.strip()}' is not a finite number")
    return value


def get_float(elem: Element, attr: str, where: str) -> float | None:
    """Attribute ``attr`` as a finite float, or None when absent.

    ``where`` names the element in errors (e.g. ``"joint 'J1' axis 'beta'"``).
    """
    text = elem.get(attr)
    if text is None:
        return None
    try:
        return _number(text, attr)
    except KinematicsError as err:
        raise err.located(line=elem.sourceline, field=where) from None


def get_vec3(elem: Element, attr: str, where: str) -> tuple[float, float, float]:
    """Attribute ``attr`` ("a b c") as three finite floats; it must be present (the schema
    fills in defaults)."""
    text = elem.get(attr)
    parts = [] if text is None else text.split()
    try:
        if len(parts) != 3:
            raise KinematicsError(f"attribute '{attr}' needs three numbers, got '{text}'")
        x, y, z = (_number(p, attr) for p in parts)
    except KinematicsError as err:
        raise err.located(line=elem.sourceline, field=where) from None
    return (x, y, z)


def get_int(elem: Element, attr: str, where: str) -> int:
    """Attribute ``attr`` as an int; it must be present (the schema fills in defaults)."""
    text = elem.get(attr)
    try:
        return int((text or "").strip())
    except ValueError:
        raise KinematicsError(f"attribute '{attr}': '{text}' is not a whole number",
                              line=elem.sourceline, field=where) from None


# -- writing --------------------------------------------------------------------------------
def format_number(x: float) -> str:
    """Shortest exact text of a number: integral values without ".0", others by ``repr``
    (which round-trips bit-exactly)."""
    x = float(x)
    if x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def format_vec(v) -> str:
    return " ".join(format_number(c) for c in v)


def quote(value: str) -> str:
    """``value`` as a double-quoted XML attribute value (escaped)."""
    if _ILLEGAL_XML_CHARS.search(value):
        raise KinematicsError(f"text {value!r} holds characters XML cannot store")
    return '"' + (value.replace("&", "&amp;").replace("<", "&lt;").replace('"', "&quot;")
                  .replace("\n", "&#10;").replace("\r", "&#13;").replace("\t", "&#9;")) + '"'


def escape_text(value: str) -> str:
    """``value`` as XML character data."""
    if _ILLEGAL_XML_CHARS.search(value):
        raise KinematicsError(f"text {value!r} holds characters XML cannot store")
    return (value.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace("\r", "&#13;"))


_ILLEGAL_XML_CHARS = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def tag(name: str, attrs: dict[str, str | None], indent: int, *, close: bool = True) -> str:
    """One line ``<name a="v" ...>`` (or ``.../>`` when ``close``), indented by ``indent``
    levels of two spaces; attributes whose value is None are left out."""
    text = "".join(f" {k}={quote(v)}" for k, v in attrs.items() if v is not None)
    return f"{'  ' * indent}<{name}{text}{'/' if close else ''}>"
