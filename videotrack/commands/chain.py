"""``videotrack chain``: show and check chain files (the body model of paper Sect. 2.1)."""

from __future__ import annotations

import argparse
import sys

from kinematics.errors import KinematicsError
from kinematics.fit.placement import RootModel, root_windows
from kinematics.model import Axis, Body, Joint
from kinematics.model.chain_xml import load_body

DESCRIPTION = """\
Inspect kinematic chain files (XML; format in docs/formats.md).

A chain file describes a body: one or more chains, each a root joint with nested segments
and joints. Every joint has three rotation axes applied as R = Ry·Rx·Rz (paper Eq. 1), each
with a name, a range in degrees and a joint-angle histogram, or locked at one value (hinge
joints lock two axes). Segments have a length and carry markers at 3D offsets.

  show   print the tree: joints, axes (range or locked value, histogram mean ± s(H)),
         segments (length, rotation), markers (offsets), root placement and units
  check  validate files against the schema and the model rules; report file:line: message
"""

EXAMPLES = """\
examples:
  videotrack chain show chains/locust_hindleg.xml
  videotrack chain check chains/*.xml
"""


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "chain", help="show or check kinematic chain files",
        description=DESCRIPTION, epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="chain_command", metavar="ACTION", required=True)

    show = sub.add_parser(
        "show", help="print a chain file as a tree",
        description="Print the body of a chain file as a tree: chains with their root, joints "
                    "with default orientation R^d and translation T, axes with range or "
                    "locked value and histogram mean ± s(H) (degrees, N = trial count), "
                    "segments with length and rotation R^s, markers with their offsets in "
                    "the segment's distal frame.",
        epilog="example:\n  videotrack chain show chains/locust_hindleg.xml",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    show.add_argument("file", metavar="FILE", help="chain file (.xml)")
    show.set_defaults(func=run_show)

    check = sub.add_parser(
        "check", help="validate chain files",
        description="Validate chain files: XML safety limits, the schema, and the model rules "
                    "(unique names, y/x/z axes, finite numbers, min <= max, root marker, "
                    "histogram values and their mass inside each axis's range), then build "
                    "the fitting problem as a fit would (markers to fit, a free axis). "
                    "Prints 'FILE: ok (...)' per valid file and 'FILE:LINE: message' per "
                    "invalid one; exits 1 if any file is invalid.",
        epilog="example:\n  videotrack chain check chains/*.xml",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    check.add_argument("files", metavar="FILE", nargs="+", help="chain files (.xml)")
    check.set_defaults(func=run_check)


def run_show(args: argparse.Namespace) -> int:
    body = load_body(args.file)
    print("\n".join(format_tree(body)))
    return 0


def run_check(args: argparse.Namespace) -> int:
    failed = 0
    for path in args.files:
        try:
            body = load_body(path)
            check_fittable(body)
        except KinematicsError as err:
            err.located(file=path)
            print(err, file=sys.stderr)
            failed += 1
        else:
            print(f"{path}: ok ({summary(body)})")
    return 1 if failed else 0


def check_fittable(body: Body) -> None:
    """Build the fitting problem of ``body`` as a fit does (with a stand-in camera per chain),
    so that ``chain check`` refuses what a fit would (no markers, no free axis, ...)."""
    from kinematics.cameras import OrthographicCamera
    from kinematics.fit.problem import FitProblem

    FitProblem.build(body, [OrthographicCamera.from_axes("check", 1.0, ("x", "-y"), (0, 0))])


def _plural(n: int, word: str, words: str | None = None) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {words or word + 's'}"


def summary(body: Body) -> str:
    """``2 chains, 6 joints, 9 free axes, 8 markers``."""
    free = sum(not r.axis.locked for r in body.axis_refs())
    return ", ".join([
        _plural(len(body.chains), "chain"), _plural(len(body.joint_names), "joint"),
        _plural(free, "free axis", "free axes"),
        _plural(len(body.marker_names), "marker"),
    ])


def _vec(v) -> str:
    return "(" + ", ".join(f"{c:g}" for c in v) + ")"


def format_tree(body: Body) -> list[str]:
    """The lines ``chain show`` prints."""
    u = body.units
    # Histogram means unwrapped next to each axis's range (φ in [120, 220] shows 170, not -190).
    means = dict(zip(body.axis_labels, body.mean_posture_deg(), strict=True))
    lines = [f"body {body.name}  [units: {u}; {summary(body)}]"]
    windows = iter(root_windows(body))
    for index, chain in enumerate(body.chains):
        lines.append(f"chain {chain.name}: root {_root_text(body, index, u)}")
        if chain.root.free:
            lines.extend(_free_root_lines(body, index, next(windows), u))
        _joint_lines(chain.root_joint, 1, u, means, lines)
    return lines


def _root_text(body: Body, index: int, u: str) -> str:
    """``fixed at ...``, ``marker M0, ...`` or ``free (...)``: the root mode comes first."""
    root = body.chains[index].root
    if root.mode == "marker":
        return (f"marker {root.marker}, followed from near {_vec(root.position)} {u} "
                "in the first frame")
    if root.free:
        return (f"free (position and orientation fitted per frame), position hint "
                f"{_vec(root.position)} {u}")
    return f"fixed at {_vec(root.position)} {u}"


def _free_root_lines(body: Body, index: int, window, u: str) -> list[str]:
    """The markers that place a free root and the search windows around the seed."""
    root = body.chains[index].root
    w_t, w_r = (float(w) for w in window)
    model = RootModel(body, index, w_t)
    if model.rigid:
        placed = "registered on markers " + ", ".join(model.names)
    else:
        placed = (f"position from marker {model.names[model.anchor]}; orientation not "
                  f"seeded (root markers {', '.join(model.names)}: fewer than three "
                  "non-collinear)")
    return [f"  root placement: {placed}",
            f"  root windows: translation ±{w_t:.4g} {u} "
            f"({_source(root.translation_window, w_t)}), "
            f"rotation ±{w_r:.4g} deg ({_source(root.rotation_window_deg, w_r)})"]


def _source(given: float | None, used: float) -> str:
    if given is None:
        return "default"
    return "set" if given == used else f"set {given:g}, capped"


def _joint_lines(
    joint: Joint, depth: int, units: str, means: dict[str, float], lines: list[str]
) -> None:
    pad = "  " * depth
    lines.append(f"{pad}joint {joint.name}: orientation {_vec(joint.orientation_deg)} deg, "
                 f"translation {_vec(joint.translation)} {units}")
    width = max(len(a.name) for a in joint.axes)
    for axis in joint.axes:
        text = _axis_text(axis, means[f"{joint.name}.{axis.name}"])
        lines.append(f"{pad}  axis {axis.name:<{width}} (rot {axis.rot})  {text}")
    for seg in joint.segments:
        lines.append(f"{pad}  segment {seg.name}: length {seg.length:g} {units}, "
                     f"rotation {_vec(seg.rotation_deg)} deg")
        for m in seg.markers:
            lines.append(f"{pad}    marker {m.name} at {_vec(m.offset)} {units}")
        for child in seg.joints:
            _joint_lines(child, depth + 2, units, means, lines)


def _axis_text(axis: Axis, mean_deg: float) -> str:
    h = axis.histogram
    if axis.locked:
        text = f"locked at {axis.locked_deg:g} deg"
        if axis.min_deg != axis.max_deg:
            text += f" (range [{axis.min_deg:g}, {axis.max_deg:g}])"
        return text
    return (f"range [{axis.min_deg:g}, {axis.max_deg:g}] deg  "
            f"H: {mean_deg:.1f} ± {h.std_deg():.1f} deg, N={h.n_trials}")
