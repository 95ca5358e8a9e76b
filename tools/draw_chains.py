"""Draw every bundled chain at its start posture (histogram means) into docs/img/.

Usage: python tools/draw_chains.py [CHAIN.xml ...]   (default: all files in chains/)

Each figure shows a top view (looking down: x anterior to the right, z right downwards) and a
side view (looking from the animal's right: x to the right, y up), with joints (circles),
segments (lines) and markers (squares, labelled).
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from kinematics.model.chain_xml import load_body
from kinematics.model.fk import forward_kinematics

REPO = Path(__file__).resolve().parents[1]


def draw(path: Path, out_dir: Path) -> Path:
    body = load_body(path)
    pose = forward_kinematics(body, body.mean_posture_deg())
    joint_index = {name: k for k, name in enumerate(body.joint_names)}
    segments = [(joint_index[j.name], k) for k, (j, _) in enumerate(body.segments())]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6))
    views = (("top view (x, z)", 0, 2), ("side view (x, y)", 0, 1))
    for ax, (title, u, v) in zip(axes, views, strict=True):
        for j, s in segments:
            a, b = pose.joints[j], pose.segment_ends[s]
            ax.plot([a[u], b[u]], [a[v], b[v]], "-", color="0.35", lw=2.5)
        ax.plot(pose.joints[:, u], pose.joints[:, v], "o", color="tab:blue", ms=7,
                label="joint centres")
        ax.plot(pose.markers[:, u], pose.markers[:, v], "s", mfc="none",
                color="tab:red", ms=9, mew=1.5, label="markers")
        if len(body.marker_names) <= 12:
            for name, p in zip(body.marker_names, pose.markers, strict=True):
                ax.annotate(name, (p[u], p[v]), xytext=(5, 5),
                            textcoords="offset points", color="tab:red", fontsize=9)
        if v == 2:
            ax.invert_yaxis()  # looking down on the animal: its right side below
        ax.set_title(title)
        ax.set_aspect("equal")
        ax.set_xlabel(f"x (anterior, {body.units})")
        ax.set_ylabel(("z (right, downwards)" if v == 2 else "y (up)") + f", {body.units}")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    fig.suptitle(f"{body.name}: {len(body.joint_names)} joints, "
                 f"{int((~body.locked_mask()).sum())} free axes, {len(body.marker_names)} "
                 f"markers — start posture (histogram means)")
    fig.tight_layout()
    out = out_dir / f"chain_{path.stem}.png"
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out


def main(argv: list[str]) -> int:
    paths = [Path(p) for p in argv] or sorted((REPO / "chains").glob("*.xml"))
    out_dir = REPO / "docs" / "img"
    out_dir.mkdir(parents=True, exist_ok=True)
    for p in paths:
        print(draw(p, out_dir))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
