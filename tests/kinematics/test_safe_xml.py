"""Hostile and broken XML: every one is refused with one KinematicsError line naming the file."""

from __future__ import annotations

import re
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from kinematics.errors import KinematicsError
from kinematics.model import safe_xml
from kinematics.model.chain_xml import load_body, loads_body
from kinematics.model.histogram_xml import loads_archive

REPO = Path(__file__).resolve().parents[2]
LOCUST = REPO / "chains" / "locust_hindleg.xml"
SECRET = "s3cr3t-7f1d2c"  # content of a file hostile documents try to read

BODY_TAIL = """
<body name="x" units="px" format="1">
  <chain name="c">
    <joint name="{name}">
      <axis rot="y" name="a" locked="0"/><axis rot="x" name="b" locked="0"/>
      <axis rot="z" name="c" locked="0"/>
    </joint>
  </chain>
</body>
"""


def refused(text, source="hostile.xml", loader=loads_body) -> str:
    """The one-line message of the KinematicsError that loading ``text`` raises."""
    with pytest.raises(KinematicsError) as info:
        loader(text, source)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(source + ":")
    return msg


@pytest.fixture
def secret_file(tmp_path) -> Path:
    path = tmp_path / "secret.txt"
    path.write_text(SECRET)
    return path


@pytest.fixture
def listener():
    """A local TCP server that records whether anything connects to it."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    server.settimeout(0.05)
    hits: list[str] = []
    stop = threading.Event()

    def serve():
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except OSError:
                continue
            hits.append("connected")
            conn.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.getsockname()[1]}", hits
    stop.set()
    thread.join()
    server.close()


# -- entities and DTDs ------------------------------------------------------------------------
@pytest.mark.parametrize("target", ["/etc/passwd", "secret"])
def test_xxe_entity_is_refused_and_never_read(target, secret_file):
    url = "file:///etc/passwd" if target == "/etc/passwd" else secret_file.as_uri()
    doc = (f'<?xml version="1.0"?>\n<!DOCTYPE body [<!ENTITY xxe SYSTEM "{url}">]>'
           + BODY_TAIL.format(name="&xxe;"))
    msg = refused(doc)
    assert "DOCTYPE" in msg
    assert SECRET not in msg and "root:" not in msg


def test_xxe_from_a_file_names_file_and_line(tmp_path, secret_file):
    path = tmp_path / "legs.xml"
    path.write_text(f'<?xml version="1.0"?>\n<!DOCTYPE body [<!ENTITY x SYSTEM '
                    f'"{secret_file.as_uri()}">]>' + BODY_TAIL.format(name="&x;"))
    with pytest.raises(KinematicsError) as info:
        load_body(path)
    assert str(info.value).startswith(f"{path}:2: ")
    assert SECRET not in str(info.value)


def test_billion_laughs_is_refused_quickly():
    lol = ['<!ENTITY lol0 "lol">'] + [
        f'<!ENTITY lol{i} "{f"&lol{i - 1};" * 10}">' for i in range(1, 10)
    ]
    doc = f"<!DOCTYPE body [{''.join(lol)}]>" + BODY_TAIL.format(name="&lol9;")
    start = time.perf_counter()
    assert "DOCTYPE" in refused(doc)
    assert time.perf_counter() - start < 1.0


def test_external_dtd_file_is_refused_and_not_read(tmp_path, secret_file):
    dtd = tmp_path / "evil.dtd"
    dtd.write_text(f'<!ENTITY leak SYSTEM "{secret_file.as_uri()}">')
    doc = f'<!DOCTYPE body SYSTEM "{dtd.as_uri()}">' + BODY_TAIL.format(name="&leak;")
    msg = refused(doc)
    assert "DOCTYPE" in msg and SECRET not in msg


def test_external_dtd_and_entity_over_http_are_never_fetched(listener):
    url, hits = listener
    docs = [
        f'<!DOCTYPE body SYSTEM "{url}/evil.dtd">' + BODY_TAIL.format(name="J0"),
        f'<!DOCTYPE body [<!ENTITY e SYSTEM "{url}/e">]>' + BODY_TAIL.format(name="&e;"),
        f'<!DOCTYPE body [<!ENTITY % p SYSTEM "{url}/p"> %p;]>' + BODY_TAIL.format(name="J0"),
    ]
    for doc in docs:
        assert "DOCTYPE" in refused(doc)
        assert "DOCTYPE" in refused(doc, loader=loads_archive)
    time.sleep(0.2)
    assert hits == []


def test_doctype_in_utf16_document_is_refused_by_the_parser():
    # The byte pre-check cannot see "<!DOCTYPE" in UTF-16; the streaming check must.
    doc = ('<?xml version="1.0" encoding="UTF-16"?>\n<!DOCTYPE body [<!ENTITY a "b">]>'
           + BODY_TAIL.format(name="J0"))
    assert "DOCTYPE" in refused(doc.encode("utf-16"))


def test_undefined_entity_is_a_syntax_error():
    msg = refused(BODY_TAIL.format(name="&xxe;").lstrip())
    assert re.match(r"hostile\.xml:3: malformed XML: .*entity 'xxe'", msg, re.I)


# -- size, depth, count -------------------------------------------------------------------------
def test_100000_deep_nesting_is_refused():
    doc = "<body>" + "<a>" * 100_000 + "</a>" * 100_000 + "</body>"
    start = time.perf_counter()
    msg = refused(doc)
    assert "nested too deeply" in msg and str(safe_xml.MAX_DEPTH) in msg
    assert time.perf_counter() - start < 1.0


def test_too_many_elements_are_refused():
    doc = "<body>\n" + "<a/>" * (safe_xml.MAX_ELEMENTS + 1) + "\n</body>"
    msg = refused(doc)
    assert "too many elements" in msg and msg.startswith("hostile.xml:2:")


def test_huge_file_is_refused_before_reading(tmp_path):
    path = tmp_path / "huge.xml"
    with open(path, "wb") as f:  # sparse: costs no disk
        f.truncate(safe_xml.MAX_BYTES + 1)
    with pytest.raises(KinematicsError) as info:
        load_body(path)
    assert str(info.value).startswith(f"{path}: file is too large")


def test_huge_text_is_refused():
    assert "too large" in refused("<body>" + " " * safe_xml.MAX_BYTES + "</body>")


# -- broken files ------------------------------------------------------------------------------
@pytest.mark.parametrize("keep", [0.1, 0.5, 0.9, 0.99])
def test_truncated_file_names_file_and_line(tmp_path, keep):
    text = LOCUST.read_text()
    path = tmp_path / "cut.xml"
    path.write_text(text[: int(len(text) * keep)])
    with pytest.raises(KinematicsError) as info:
        load_body(path)
    msg = str(info.value)
    assert re.match(rf"{re.escape(str(path))}:\d+: ", msg) and "\n" not in msg


def test_truncated_file_says_what_is_unclosed():
    text = LOCUST.read_text()
    msg = refused(text[: text.index("</chain>")])
    assert "truncated" in msg and "<chain>" in msg


@pytest.mark.parametrize("content", [b"", b"   \n\t", b"\xef\xbb\xbf"])
def test_empty_file(tmp_path, content):
    path = tmp_path / "empty.xml"
    path.write_bytes(content)
    with pytest.raises(KinematicsError) as info:
        load_body(path)
    assert str(info.value).startswith(str(path) + ":")


@pytest.mark.parametrize(("doc", "found"), [
    ("<foo/>", "<foo>"),
    ('<histogram-archive format="1"/>', "<histogram-archive>"),
    ("<x:body xmlns:x='urn:x'/>", "body"),
])
def test_wrong_root_element(doc, found):
    msg = refused(doc)
    assert found in msg and "expected <body>" in msg


def test_chain_file_is_not_an_archive():
    msg = refused(LOCUST.read_text(), loader=loads_archive)
    assert "root element is <body>, expected <histogram-archive>" in msg


@pytest.mark.parametrize(("data", "words"), [
    (b'<body name="\xff\xfe" units="px" format="1"/>', "encoding"),
    (b'<?xml version="1.0" encoding="klingon"?><body/>', "encoding"),
    (b"<body><chain></body>", "mismatch"),
    (b"<body/><body/>", "extra content"),
    (b"not xml at all", "start tag"),
])
def test_syntax_errors_are_one_line(data, words):
    assert words in refused(data).lower()


def test_text_that_is_not_unicode():
    assert "not valid Unicode" in refused('<body name="\ud800"/>')


def test_missing_file_and_directory(tmp_path):
    for path in (tmp_path / "nope.xml", tmp_path):
        with pytest.raises(KinematicsError) as info:
            load_body(path)
        assert str(info.value).startswith(f"{path}: cannot read file")


# -- schema messages ----------------------------------------------------------------------------
def test_schema_errors_are_short_and_name_the_element():
    text = LOCUST.read_text().replace('min="120"', 'min="abc"')
    msg = refused(text)
    assert msg == "hostile.xml:12: <axis name=\"phi\">: attribute 'min': 'abc' is not a number"


def test_schema_fills_in_defaults():
    root = safe_xml.parse_document(LOCUST.read_bytes(), "x.xml", "body")
    joint = root.find("chain/joint")
    assert joint.get("orientation") == "0 0 0" and joint.get("translation") == "0 0 0"


# -- writing helpers ---------------------------------------------------------------------------
def test_format_number_is_short_and_exact():
    assert [safe_xml.format_number(x) for x in (13.0, -40, 0.1, 1e20, -0.0, 2.5)] == [
        "13", "-40", "0.1", "1e+20", "0", "2.5"]
    rng = np.random.default_rng(1)
    values = np.concatenate([rng.normal(size=200) * 10.0 ** rng.integers(-300, 300, 200),
                             [np.nextafter(1.0, 2.0), 5e-324, 1.7976931348623157e308]])
    for x in values:
        assert float(safe_xml.format_number(x)) == x


def test_quoted_text_survives_a_parse():
    name = 'a "b" & <c>\n\ttab'
    line = safe_xml.tag("histogram-archive", {"format": "1", "body": "x"}, 0, close=False)
    doc = line + f"<description>{safe_xml.escape_text(name + chr(13))}</description>" \
        "</histogram-archive>"
    assert loads_archive(doc).description == name + "\r"
    with pytest.raises(KinematicsError):
        safe_xml.quote("bell\x07")


def test_only_safe_xml_imports_lxml():
    importers = sorted(
        str(p.relative_to(REPO)) for pkg in ("kinematics", "videotrack", "ui")
        for p in (REPO / pkg).rglob("*.py")
        if re.search(r"^\s*(import lxml|from lxml)", p.read_text(), re.M)
    )
    assert importers == ["kinematics/model/safe_xml.py"]


def test_chains_load_from_many_threads_at_once():
    """The shared schema is built and used under a lock (libxml2 is not re-entrant)."""
    from concurrent.futures import ThreadPoolExecutor
    from pathlib import Path

    from kinematics.model import safe_xml
    from kinematics.model.chain_xml import load_body

    safe_xml._schema.cache_clear()
    path = Path(__file__).resolve().parents[2] / "chains" / "fly_six_legs.xml"
    with ThreadPoolExecutor(8) as pool:
        bodies = list(pool.map(lambda _: load_body(path), range(32)))
    assert all(b == bodies[0] for b in bodies)
