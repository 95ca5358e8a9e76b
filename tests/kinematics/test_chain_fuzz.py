"""Property test: thousands of mutated chain files and archives give a Body (or archive) or our
KinematicsError with a one-line located message — never another exception.

Reproducible: ``derandomize=True`` makes every run (and CI) draw the same examples. Set
``VIDEOTRACK_FUZZ_EXAMPLES`` to run more locally.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from kinematics.errors import KinematicsError
from kinematics.model import Body
from kinematics.model.chain_xml import body_to_string, load_body, loads_body
from kinematics.model.histogram_xml import (
    HistogramArchive,
    apply_archive,
    archive_from_body,
    archive_to_string,
    loads_archive,
)

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = int(os.environ.get("VIDEOTRACK_FUZZ_EXAMPLES", "2500"))
SOURCE = "mutant.xml"


def _seeds() -> list[str]:
    files = sorted((REPO / "chains").glob("*.xml"))
    texts = [p.read_text(encoding="utf-8") for p in files]
    # A chain file with a histograms section and an archive, so their parsing is mutated too.
    body = load_body(files[0])
    rng = np.random.default_rng(0)
    learned = archive_from_body(body)
    learned = HistogramArchive(
        {k: h.updated(rng.uniform(-180, 180, 3)) for k, h in list(learned.items())[:2]},
        body=body.name,
    )
    texts.append(body_to_string(apply_archive(body, learned)))
    texts.append(archive_to_string(learned))
    return texts


SEEDS = _seeds()
ATTRIBUTE = re.compile(r'([\w-]+)="([^"]*)"')

odd_values = st.sampled_from([
    "", " ", "NaN", "nan", "INF", "-INF", "1e400", "-0", "0 0", "0 0 0 0", "1e-400", "+5",
    "0x10", "1_0", "marker", "fixed", "y", "x", "z", "px", "mm", "360", "36001", "-180", "180",
    "J0", "M0", "hindleg", "phi", "&amp;", "&lt;", "&#10;", "&#0;", "&xxe;", "1" * 400,
])
values = st.one_of(
    odd_values,
    st.text(max_size=12).filter(lambda s: '"' not in s),
    st.integers(-10**30, 10**30).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
)
junk = st.text(alphabet=st.sampled_from([*"<>/&;\"'=!-[]?% \n\tazAZ09.#", "é", "\u00a0"]),
               min_size=1, max_size=10)


def mutate(data: st.DataObject, text: str) -> str:
    """Apply one random mutation to ``text``."""
    lines = text.split("\n")
    kind = data.draw(st.sampled_from(
        ["delete", "duplicate", "swap", "cut", "attribute", "attribute", "insert", "insert"]))
    if kind in ("delete", "duplicate", "swap") and len(lines) > 1:
        i = data.draw(st.integers(0, len(lines) - 1))
        if kind == "delete":
            del lines[i]
        elif kind == "duplicate":
            lines.insert(i, lines[i])
        else:
            j = data.draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        return "\n".join(lines)
    if kind == "cut":
        return text[: data.draw(st.integers(0, len(text)))]
    matches = list(ATTRIBUTE.finditer(text))
    if kind == "attribute" and matches:
        m = matches[data.draw(st.integers(0, len(matches) - 1))]
        return text[: m.start(2)] + data.draw(values) + text[m.end(2):]
    at = data.draw(st.integers(0, len(text)))
    return text[:at] + data.draw(junk) + text[at:]


def check_outcome(loader, text: str) -> None:
    try:
        result = loader(text, SOURCE)
    except KinematicsError as err:
        msg = str(err)
        assert msg.startswith(SOURCE + ":"), msg
        assert "\n" not in msg and "Traceback" not in msg, msg
    else:
        assert isinstance(result, Body | HistogramArchive)


@settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(data=st.data())
def test_mutated_files_load_or_raise_our_error(data):
    text = SEEDS[data.draw(st.integers(0, len(SEEDS) - 1))]
    for _ in range(data.draw(st.integers(1, 6))):
        text = mutate(data, text)
    check_outcome(loads_body, text)
    check_outcome(loads_archive, text)


def test_seeds_are_valid():
    for text in SEEDS:
        try:
            loads_body(text)
        except KinematicsError:
            loads_archive(text)
