"""Fault injection: whatever happens to files, disks or processes, does a batch end with
complete and right outputs, say what went wrong, and never print a traceback?

Run from the repository root::

    python bench/bench_faults.py [--trials 4] [--frames 24] [--kills 8] [--repeats 3]

A project of ``--trials`` synthetic trials (the paper's locust set-up, a short schedule,
``--n-end``) is made once: every trial's video is re-encoded uncompressed (so all have the
same byte size, as the raw files of lab cameras), and the last trial is a folder of PNG
images. One uninterrupted ``videotrack batch`` on a copy gives the reference outputs; the
outputs do not depend on where the project is, so every fault below is run on a fresh copy
and compared byte for byte with the reference. Every command runs as a user runs it
(``python -m videotrack`` in a subprocess), and its stderr is searched for tracebacks.

Faults (each row of the table):

- kill -9 of a batch (``--jobs`` 1 or 2, alternately) at a random moment, then the same
  command again: every output identical to the reference, no temporary file left;
- a video truncated at a random byte: the trial is ``incomplete`` (exit 3) naming the video,
  in this run and the next, the other trials untouched;
- an image of the image folder truncated: ``incomplete`` naming the image (or, for the first
  image, ``failed`` naming it);
- random bytes written over part of a video (same size, same name): never ``up to date``;
  the new detections record the new content's hash;
- two trials' videos swapped (same size): both recomputed, each with the other's results;
- random bytes in the chain or the camera file: no trial ``up to date`` on the old results;
- the finished project moved or copied elsewhere: every trial up to date, nothing
  recomputed, no log written; after ``--force`` the same bytes;
- two batches started at once: one runs, the other is refused in one line (or finds all up
  to date); outputs identical;
- disk full (a small tmpfs, where the machine allows mounting one): the batch fails with a
  one-line message, then on a larger disk the same command completes to the reference.

Columns: faults tried; outputs checked (trial output sets compared, plus states and
messages); outputs lost (a trial's outputs missing after recovery); outputs wrong (differing
bytes, a stale result reported up to date, a missing or wrong state, message or warning, a
temporary file left); tracebacks (in any command's stderr). The goal is 0 lost, 0 wrong,
0 tracebacks.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from _report import machine  # noqa: E402

INPUTS = {"video.avi", "truth.csv", "config.toml"}
ENV: dict[str, str] = {}


def vt(*args, timeout: float = 600) -> tuple[int, str, str]:
    """``python -m videotrack ARGS`` as a user runs it: (exit status, stdout, stderr)."""
    proc = subprocess.run([sys.executable, "-m", "videotrack", *map(str, args)],
                          capture_output=True, text=True, env=ENV, timeout=timeout)
    return proc.returncode, proc.stdout, proc.stderr


def outputs(root: Path) -> dict[str, bytes]:
    """Every file a batch wrote into the trial folders, by path relative to the project."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.parent != root and p.parent.name not in ("logs", "frames")
            and p.name not in INPUTS}


def strays(root: Path) -> list[str]:
    return sorted(p.name for p in root.rglob("*") if p.name.startswith(".")
                  or ".partial" in p.name)


def summary(root: Path) -> dict[str, dict]:
    with contextlib.suppress(FileNotFoundError):
        return {r["trial"]: r for r in csv.DictReader((root / "summary.csv").open())}
    return {}


def tracebacks(*texts: str) -> int:
    return sum(t.count("Traceback (most recent call last)") for t in texts)


class Row:
    def __init__(self, name: str) -> None:
        self.name, self.tried, self.checked, self.lost, self.wrong, self.tb = name, 0, 0, 0, 0, 0
        self.notes: list[str] = []
        self.detail = ""

    def check(self, ok: bool, note: str, lost: bool = False) -> None:
        self.checked += 1
        if not ok:
            if lost:
                self.lost += 1
            else:
                self.wrong += 1
            self.notes.append(note)

    def compare(self, got: dict, want: dict, trials, where: str) -> None:
        """One check per trial: its outputs, byte for byte."""
        for trial in trials:
            mine = {k: v for k, v in got.items() if k.startswith(trial + "/")}
            ref = {k: v for k, v in want.items() if k.startswith(trial + "/")}
            missing = set(ref) - set(mine)
            self.check(not missing, f"{where}: {trial}: lost {sorted(missing)}", lost=True)
            if not missing:
                self.check(mine == ref, f"{where}: {trial}: outputs differ")


def make_project(root: Path, trials: int, frames: int, anneal: dict) -> list[str]:
    """The synthetic project: raw (uncompressed) videos, the last trial a PNG folder."""
    import cv2

    from videotrack.detect.video import VideoSource
    from videotrack.synth.paper_setup import write_example_project
    from videotrack.synth.project import trial_names

    names = trial_names(trials)
    write_example_project(root, names, frames, anneal)
    for k, name in enumerate(names):
        folder = root / name
        with VideoSource(folder / "video.avi") as video:
            images = [f.copy() for _, f in video.frames()]
        if k == len(names) - 1:
            (folder / "frames").mkdir()
            for i, image in enumerate(images):
                cv2.imwrite(str(folder / "frames" / f"{i:04d}.png"), image)
            (folder / "video.avi").unlink()
            (folder / "config.toml").write_text('[video]\npath = "frames"\n')
            continue
        h, w = images[0].shape
        writer = cv2.VideoWriter(str(folder / "video.avi"), cv2.VideoWriter_fourcc(*"Y800"),
                                 50.0, (w, h), isColor=False)
        for image in images:
            writer.write(image)
        writer.release()
    return names


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=4)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--n-end", type=int, default=35000)
    ap.add_argument("--kills", type=int, default=12)
    ap.add_argument("--repeats", type=int, default=3, help="tries of each other fault")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--verbose", action="store_true", help="list every wrong or lost output")
    args = ap.parse_args()
    rng = random.Random(args.seed)
    scale = args.n_end / 35000
    anneal = {"n_end": args.n_end, "n_l": max(1, round(3500 * scale)),
              "n_tau": max(1, round(1500 * scale))}
    with tempfile.TemporaryDirectory(prefix="bench-faults-") as tmp:
        tmp = Path(tmp)
        ENV.update({**os.environ, "PYTHONPATH": str(REPO),
                    "VIDEOTRACK_CACHE_DIR": str(tmp / "cache")})
        pristine = tmp / "pristine"
        names = make_project(pristine, args.trials, args.frames, anneal)
        videos = names[:-1]
        images = names[-1]
        ref_root = tmp / "reference"
        shutil.copytree(pristine, ref_root)
        vt("--version")  # (a first start compiles nothing, but warms the disk cache)
        t0 = time.perf_counter()
        vt("--version")
        t_start = time.perf_counter() - t0
        t0 = time.perf_counter()
        code, _, err = vt("batch", ref_root, "--jobs", "1")
        t_full = time.perf_counter() - t0
        if code != 0:
            print(err)
            return 1
        reference = outputs(ref_root)
        print(f"Fault injection: {args.trials} trials x {args.frames} frames (the last an "
              f"image folder), N_end {args.n_end}; a full batch takes {t_full:.1f} s, "
              f"{t_start:.1f} s of it starting Python; {machine()}\n")
        rows = []
        counter = iter(range(10**6))

        def fresh(finished: bool = False) -> Path:
            target = tmp / f"w{next(counter)}"
            shutil.copytree(ref_root if finished else pristine, target)
            return target

        # -- kill -9 ------------------------------------------------------------------------
        row = Row("kill -9 at a random moment, then run again")
        progress = []
        for k in range(args.kills):
            work = fresh()
            jobs = "1" if k % 2 == 0 else "2"
            proc = subprocess.Popen([sys.executable, "-m", "videotrack", "batch", str(work),
                                     "--jobs", jobs], stdout=subprocess.DEVNULL,
                                    stderr=subprocess.PIPE, env=ENV, start_new_session=True)
            # most kills while trials are processed, some while the batch starts
            start = 0.0 if k % 4 == 3 else t_start
            time.sleep(start + rng.uniform(0.0, 1.0) * (t_full - start))
            with contextlib.suppress(ProcessLookupError):
                os.kill(proc.pid, signal.SIGKILL)
            killed_err = proc.communicate()[1].decode(errors="replace")
            time.sleep(0.3)  # pool workers die with the batch (PR_SET_PDEATHSIG)
            found = outputs(work)
            progress.append((sum(n.endswith(".npz") for n in found),
                             sum(n.endswith("results.csv") for n in found),
                             len(list(work.rglob("*.partial")))))
            code, _, err = vt("batch", work, "--jobs", "1")
            row.tried += 1
            row.tb += tracebacks(killed_err, err)
            row.check(code == 0, f"kill {k}: rerun exit {code}: {err[-300:]}")
            row.compare(outputs(work), reference, names, f"kill {k}")
            row.check(not strays(work), f"kill {k}: left {strays(work)}")
        row.detail = ("killed with (detections, results, checkpoints) of the "
                      f"{len(names)} trials on disk: " + ", ".join(
                          f"({a}, {b}, {c})" for a, b, c in progress))
        rows.append(row)

        # -- truncated video ----------------------------------------------------------------
        row = Row("video truncated at a random byte")
        for k in range(args.repeats):
            work = fresh(finished=True)
            trial = rng.choice(videos)
            video = work / trial / "video.avi"
            data = video.read_bytes()
            video.write_bytes(data[: int(len(data) * rng.uniform(0.15, 0.9))])
            row.tried += 1
            for attempt in range(2):  # the warning survives the rerun
                code, out, err = vt("batch", work, "--jobs", "1")
                row.tb += tracebacks(err)
                state = summary(work).get(trial, {})
                row.check(code == 3, f"truncate {k}.{attempt}: exit {code}")
                row.check(state.get("state") == "incomplete"
                          and "video.avi" in state.get("message", "")
                          and "video.avi: decoding stopped at frame" in state.get("warnings", ""),
                          f"truncate {k}.{attempt}: {state}")
            row.compare(outputs(work), reference, [n for n in names if n != trial],
                        f"truncate {k}")
        rows.append(row)

        # -- truncated image ----------------------------------------------------------------
        row = Row("image of an image folder truncated")
        for _ in range(args.repeats):
            work = fresh(finished=True)
            i = rng.randrange(args.frames)
            image = work / images / "frames" / f"{i:04d}.png"
            image.write_bytes(image.read_bytes()[: rng.randrange(1, image.stat().st_size // 2)])
            row.tried += 1
            code, out, err = vt("batch", work, "--jobs", "1")
            row.tb += tracebacks(err)
            state = summary(work).get(images, {})
            wanted = ("incomplete", 3) if i else ("failed", 1)
            row.check((state.get("state"), code) == wanted and image.name in
                      state.get("message", "") + state.get("warnings", ""),
                      f"image {i}: exit {code}, {state}")
            row.compare(outputs(work), reference, videos, f"image {i}")
        rows.append(row)

        # -- corrupt bytes, same size -------------------------------------------------------
        from videotrack.project.identity import sha256_of

        row = Row("random bytes over part of a video (same size)")
        for k in range(args.repeats):
            work = fresh(finished=True)
            trial = rng.choice(videos)
            video = work / trial / "video.avi"
            data = bytearray(video.read_bytes())
            at = rng.randrange(len(data) // 4, len(data) - 4096)
            data[at:at + 4096] = rng.randbytes(4096)
            video.write_bytes(bytes(data))
            row.tried += 1
            code, out, err = vt("batch", work, "--jobs", "1")
            row.tb += tracebacks(err)
            state = summary(work).get(trial, {}).get("state", "")
            row.check(not state.startswith("up"), f"corrupt {k}: {trial} {state}")
            det = work / trial / "video.detections.npz"
            if det.exists():
                import numpy as np

                with np.load(det) as z:
                    meta = json.loads(str(z["metadata"]))
                row.check(meta["videos"][0]["sha256"] == sha256_of(video),
                          f"corrupt {k}: detections do not record the new content")
            row.compare(outputs(work), reference, [n for n in names if n != trial],
                        f"corrupt {k}")
        rows.append(row)

        # -- same-size swap -----------------------------------------------------------------
        row = Row("two trials' videos swapped (same size)")
        for k in range(max(1, args.repeats - 1)):
            if len(videos) < 2:
                break
            work = fresh(finished=True)
            a, b = rng.sample(videos, 2)
            va, vb = work / a / "video.avi", work / b / "video.avi"
            da, db = va.read_bytes(), vb.read_bytes()
            va.write_bytes(db)
            vb.write_bytes(da)
            row.tried += 1
            code, out, err = vt("batch", work, "--jobs", "1")
            row.tb += tracebacks(err)
            states = summary(work)
            for mine, other in ((a, b), (b, a)):
                row.check(states.get(mine, {}).get("state") == "done",
                          f"swap {k}: {mine} {states.get(mine)}")
                got = (work / mine / "video.results.csv").read_bytes() if (
                    work / mine / "video.results.csv").exists() else None
                row.check(got == reference[f"{other}/video.results.csv"],
                          f"swap {k}: {mine} has not {other}'s results")
        rows.append(row)

        # -- corrupt chain / cameras --------------------------------------------------------
        row = Row("random bytes in the chain or camera file")
        for k in range(args.repeats + 1):
            work = fresh(finished=True)
            target = work / ("chain.xml" if k % 2 == 0 else "cameras.toml")
            data = bytearray(target.read_bytes())
            for _ in range(rng.randint(1, 4)):
                data[rng.randrange(len(data))] = rng.randrange(256)
            target.write_bytes(bytes(data))
            row.tried += 1
            code, out, err = vt("batch", work, "--jobs", "1")
            row.tb += tracebacks(err, out)
            for trial, state in summary(work).items():
                row.check(not state["state"].startswith("up"),
                          f"{target.name} {k}: {trial} reused stale results")
            row.check(code in (0, 1, 3), f"{target.name} {k}: exit {code}")
        rows.append(row)

        # -- moved and copied projects ------------------------------------------------------
        row = Row("finished project moved or copied")
        for k in range(2):
            work = fresh(finished=True)
            elsewhere = tmp / f"elsewhere{k}" / "deeper" / "project"
            elsewhere.parent.mkdir(parents=True)
            if k == 0:
                os.rename(work, elsewhere)
            else:
                shutil.copytree(work, elsewhere)
            row.tried += 1
            code, out, err = vt("batch", elsewhere, "--dry-run")
            row.tb += tracebacks(err)
            row.check(f"0 to process, {len(names)} up to date" in out, f"move {k}: {out}")
            code, out, err = vt("batch", elsewhere, "--jobs", "1")
            row.tb += tracebacks(err)
            row.check(code == 0 and "no log (nothing to do)" in out, f"move {k}: {out}")
            row.compare(outputs(elsewhere), reference, names, f"move {k}")
            code, out, err = vt("batch", elsewhere, "--jobs", "1", "--force")
            row.tb += tracebacks(err)
            row.compare(outputs(elsewhere), reference, names, f"move {k} --force")
        rows.append(row)

        # -- concurrent batches -------------------------------------------------------------
        row = Row("two batches at once on one project")
        for k in range(args.repeats):
            work = fresh()
            procs = [subprocess.Popen([sys.executable, "-m", "videotrack", "batch", str(work),
                                       "--jobs", "1"], stdout=subprocess.PIPE,
                                      stderr=subprocess.PIPE, text=True, env=ENV)
                     for _ in range(2)]
            results = [(*reversed(p.communicate()), p.returncode) for p in procs]
            results = [(code, out, err) for err, out, code in results]
            row.tried += 1
            row.tb += tracebacks(*(r[2] for r in results))
            codes = sorted(r[0] for r in results)
            refused = [r for r in results if r[0] == 1]
            row.check(codes in ([0, 0], [0, 1]) and all(
                "another 'videotrack batch' is running" in r[2] and r[2].count("\n") == 1
                for r in refused), f"concurrent {k}: {codes}")
            row.compare(outputs(work), reference, names, f"concurrent {k}")
        rows.append(row)

        # -- disk full ----------------------------------------------------------------------
        row = Row("disk full (tmpfs), then room again")
        full: list[int] = []
        mount = tmp / "small"
        mount.mkdir()
        def pages(n: int) -> int:
            return -(-n // 4096) * 4096

        inputs = sum(pages(p.stat().st_size) for p in pristine.rglob("*") if p.is_file())
        needed = sum(pages(len(v)) for v in reference.values()) + 65536  # + summary, log
        mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={inputs + 65536}",
                                  "tmpfs", str(mount)], capture_output=True).returncode == 0
        try:
            for k in range(args.repeats if mounted else 0):
                room = inputs + 65536 + int(needed * rng.uniform(0.0, 0.9))
                for p in mount.iterdir():  # emptied first: a tmpfs cannot shrink below its use
                    shutil.rmtree(p) if p.is_dir() else p.unlink()
                subprocess.run(["mount", "-o", f"remount,size={room}", str(mount)], check=True,
                               capture_output=True)
                work = mount / "project"
                try:
                    shutil.copytree(pristine, work)
                except OSError:
                    continue
                row.tried += 1
                code, out, err = vt("batch", work, "--jobs", "1")
                row.tb += tracebacks(err, out)
                row.check(code in (0, 1), f"disk {k}: exit {code}")
                full.append(code)
                subprocess.run(["mount", "-o", f"remount,size={room + 4 * needed + 2**20}",
                                str(mount)], check=True, capture_output=True)
                code, out, err = vt("batch", work, "--jobs", "1")
                row.tb += tracebacks(err, out)
                row.check(code == 0, f"disk {k}: after room, exit {code}: {err[-300:]}")
                row.compare(outputs(work), reference, names, f"disk {k}")
                row.check(not strays(work), f"disk {k}: left {strays(work)}")
        except subprocess.CalledProcessError as err:  # remounting refused: no such row
            print(f"(disk full: stopped, {' '.join(err.cmd)} failed)")
            mounted = False
        finally:
            subprocess.run(["umount", str(mount)], capture_output=True)
        if mounted:
            row.detail = (f"{sum(c == 1 for c in full)} of {len(full)} batches on the full disk "
                          "failed (exit 1, one line per failed trial)")
            rows.append(row)
        else:
            print("(disk full: skipped, no tmpfs could be mounted here)")

    print("| fault | tried | outputs checked | lost | wrong | tracebacks |")
    print("| --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r.name} | {r.tried} | {r.checked} | {r.lost} | {r.wrong} | {r.tb} |")
    total = [sum(getattr(r, a) for r in rows) for a in ("tried", "checked", "lost", "wrong",
                                                          "tb")]
    print(f"| **all** | {total[0]} | {total[1]} | {total[2]} | {total[3]} | {total[4]} |")
    print("\ngoal: 0 lost, 0 wrong, 0 tracebacks")
    for r in rows:
        if r.detail:
            print(f"{r.name}: {r.detail}")
    notes = [n for r in rows for n in r.notes]
    for note in notes if args.verbose else notes[:10]:
        print(f"  {note}")
    return 0 if not (total[2] or total[3] or total[4]) else 1


if __name__ == "__main__":
    sys.exit(main())
