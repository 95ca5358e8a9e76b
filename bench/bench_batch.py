"""Batch processing: parallel speed-up, Dask against local, memory, and kill -9 / resume.

Run from the repository root::

    python bench/bench_batch.py [--trials 20] [--frames 60] [--repeats 2] [--kills 3]

A project of ``--trials`` synthetic trials (the paper's locust set-up, ``--frames`` frames
each, Table 1 schedule unless ``--n-end``; ``videotrack.synth.paper_setup.write_example_project``)
is processed by the ``videotrack batch`` command in a subprocess, as a user runs it, timing
the wall clock of the whole command (start-up included), after one untimed run that fills
numba's cache:

- ``--jobs 1`` (the trials one after the other, each fitted on every core), ``--jobs 1`` on
  one thread (``NUMBA_NUM_THREADS=1``), and ``--jobs 2`` (two worker processes, one thread
  each), each with ``--force``; every run's outputs are compared byte for byte;
- ``--scheduler`` on a ``dask.distributed.LocalCluster`` of 2 worker processes with one
  thread each, started beforehand and warmed by one batch (an existing cluster);
- the peak memory (largest process, ``ru_maxrss``) of ``--jobs 2`` on a quarter, half and
  all of the trials;
- ``--kills`` times: a fresh batch (``--jobs 2``) killed with SIGKILL at a random moment,
  then run again; the outputs are compared with the uninterrupted run's and the project is
  searched for temporary files, checkpoints and surviving worker processes.
"""

from __future__ import annotations

import argparse
import os
import platform
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from videotrack.synth.paper_setup import write_example_project

INPUTS = {"video.avi", "truth.csv", "config.toml"}


def batch(project: Path, *args: str, env: dict | None = None) -> float:
    """Wall time of one ``videotrack batch`` command (it must succeed)."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "videotrack", "batch", str(project), *args],
                   check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   env={**os.environ, **(env or {})})
    return time.perf_counter() - t0


def outputs(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.parent != root and p.parent.name != "logs"
            and p.name not in INPUTS}


def clear(root: Path) -> None:
    for path in outputs(root):
        (root / path).unlink()


def strays(root: Path) -> list[str]:
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*")
                  if p.name.startswith(".") or ".partial" in p.name)


def peak_rss_mb(project: Path, *args: str) -> float:
    """Largest resident set of the batch command and its workers, MiB."""
    code = ("import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, "
            "stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL); "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")
    out = subprocess.run([sys.executable, "-c", code, sys.executable, "-m", "videotrack",
                          "batch", str(project), *args], check=True, capture_output=True,
                         text=True)
    return int(out.stdout) / 1024


def descendants(pid: int) -> list[int]:
    """Child processes (recursively) of ``pid``, from /proc."""
    found, todo = [], [pid]
    while todo:
        p = todo.pop()
        for task in Path(f"/proc/{p}/task").glob("*/children"):
            with open(task) as fh:
                kids = [int(k) for k in fh.read().split()]
            found += kids
            todo += kids
    return found


def kill_and_resume(project: Path, reference: dict, t_full: float, rng) -> dict:
    clear(project)
    proc = subprocess.Popen([sys.executable, "-m", "videotrack", "batch", str(project),
                             "--jobs", "2"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    at = rng.uniform(0.05, 0.95) * t_full
    time.sleep(at)
    workers = descendants(proc.pid)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    time.sleep(0.5)
    alive = [w for w in workers if Path(f"/proc/{w}").exists()
             and "zombie" not in Path(f"/proc/{w}/status").read_text().lower()]
    done = sum(name.endswith("results.csv") for name in outputs(project))
    left = strays(project)
    batch(project, "--jobs", "2")
    return {"at": at, "done": done, "left": len(left), "alive": len(alive),
            "identical": outputs(project) == reference, "strays": strays(project)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--n-end", type=int, help="annealing iterations (default: Table 1)")
    ap.add_argument("--repeats", type=int, default=2, help="timed runs of each; the best")
    ap.add_argument("--kills", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0, help="seed of the kill moments")
    args = ap.parse_args()
    anneal = None
    if args.n_end:
        scale = args.n_end / 35000
        anneal = {"n_end": args.n_end, "n_l": max(1, round(3500 * scale)),
                  "n_tau": max(1, round(1500 * scale))}
    rng = random.Random(args.seed)
    print(f"Batch benchmark: {args.trials} trials x {args.frames} frames, N_end "
          f"{args.n_end or 35000}; {platform.machine()}, {os.cpu_count()} CPUs, "
          f"Python {platform.python_version()}\n")
    with tempfile.TemporaryDirectory() as tmp:
        project = Path(tmp) / "project"
        write_example_project(project, args.trials, args.frames, anneal)
        batch(project, "--jobs", "1")  # numba's cache, and the reference outputs
        reference = outputs(project)
        rows = []

        def timed(label, *extra, env=None):
            t, same = float("inf"), True
            for _ in range(args.repeats):
                t = min(t, batch(project, "--force", *extra, env=env))
                same &= outputs(project) == reference
            rows.append((label, t, same))
            return t

        t1 = timed("--jobs 1 (one process, every core)", "--jobs", "1")
        t1s = timed("--jobs 1, one thread", "--jobs", "1", env={"NUMBA_NUM_THREADS": "1"})
        t2 = timed("--jobs 2 (two processes, one thread each)", "--jobs", "2")
        from dask.distributed import LocalCluster

        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster:
            batch(project, "--force", "--scheduler", cluster.scheduler_address)  # warm
            td = timed("Dask LocalCluster, 2 workers x 1 thread", "--scheduler",
                       cluster.scheduler_address)
        n = args.trials * args.frames
        print("| run | wall time | frames/s | outputs identical to --jobs 1 |")
        print("| --- | --- | --- | --- |")
        for label, t, same in rows:
            print(f"| {label} | {t:.1f} s | {n / t:.0f} | {'yes' if same else 'NO'} |")
        print(f"\nratios: --jobs 2 / --jobs 1 = {t2 / t1:.2f} (goal <= 0.6); --jobs 2 / --jobs 1 "
              f"on one thread = {t2 / t1s:.2f}; Dask / --jobs 2 = {td / t2:.2f} (goal within "
              "25 %)")

        print("\n| trials | peak memory of the largest process, --jobs 2 |")
        print("| --- | --- |")
        for k in sorted({max(1, args.trials // 4), max(1, args.trials // 2), args.trials}):
            sel = [f"--trial={name}" for name in sorted({p.split("/video")[0] for p in
                                                         reference})[:k]]
            print(f"| {k} | {peak_rss_mb(project, '--force', '--jobs', '2', *sel):.0f} MiB |")

        print(f"\n| kill -9 at | trials finished | temporary files left | workers alive "
              f"after 0.5 s | rerun identical | temporary files after |\n{'| --- ' * 6}|")
        for _ in range(args.kills):
            r = kill_and_resume(project, reference, t2, rng)
            print(f"| {r['at']:.1f} s | {r['done']} of {args.trials} | {r['left']} | "
                  f"{r['alive']} | {'yes' if r['identical'] else 'NO'} | "
                  f"{len(r['strays'])} |")
        shutil.rmtree(project / "logs", ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
