"""Write docs/cli.md, the command-line reference, from the commands' own argparse parsers.

Run from the repository root after changing a command's options or help::

    python tools/make_cli_docs.py          # rewrite docs/cli.md
    python tools/make_cli_docs.py --check  # exit 1 if docs/cli.md is out of date

The test suite checks that docs/cli.md is what this script writes.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tools._docgen import update_generated_file
from videotrack.cli import build_parser

DOC = Path(__file__).resolve().parents[1] / "docs" / "cli.md"
#: Help is formatted for this terminal width, whatever the terminal running the script.
WIDTH = 100

HEADER = """\
# Command-line reference

Every command and option of `videotrack`, as `videotrack COMMAND --help` prints it. This page
is generated from the commands themselves by `python tools/make_cli_docs.py` (a test checks it
is up to date); the guides explain the ideas behind the options: [getting started](
getting-started.md), [concepts](concepts.md), [batch processing](batch.md), [the config
file](config.md).
"""


def _subcommands(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    found = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in dict.fromkeys(action.choices.values()):  # aliases share a parser
                found.append(sub)
    return found


def render() -> str:
    """The text of docs/cli.md."""
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(WIDTH)  # argparse wraps to $COLUMNS
    try:
        parser = build_parser()
        parts = [HEADER]
        todo = [(parser, 2)]
        while todo:
            p, level = todo.pop(0)
            parts.append(f"{'#' * level} `{p.prog}`\n\n```text\n{p.format_help().rstrip()}\n"
                         "```\n")
            # commands under ##, like the top level; their actions (chain show) under ###
            todo[:0] = [(sub, 2 if p is parser else 3) for sub in _subcommands(p)]
        return "\n".join(parts)
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only check; exit 1 if out of date")
    args = ap.parse_args()
    return update_generated_file(DOC, render(), args.check, "run python tools/make_cli_docs.py")


if __name__ == "__main__":
    sys.exit(main())
