"""``videotrack batch``: detect and fit every trial of a project, resumably, on all cores or
a Dask cluster."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

EXAMPLES = """\
examples:
  # every trial of the project, one per core; run it again after a crash or a reboot
  videotrack batch myproject
  # what would run, and why (nothing is written)
  videotrack batch myproject --dry-run
  # two trials of the folder session1 again, recomputing although they are up to date
  videotrack batch myproject --trial 'session1/trial0[12]' --force
  # on a Dask cluster (a scheduler address, or the file 'dask scheduler' wrote)
  videotrack batch myproject --scheduler tcp://head-node:8786

a project (see docs/batch.md):
  myproject/config.toml                 settings all trials share, e.g.
                                          [chain]      path = "chain.xml"
                                          [cameras]    path = "cameras.toml"
                                          [[views]] ... [[filters.steps]] ...
  myproject/session1/config.toml        optional: keys that differ in session1/
  myproject/session1/trial01/walk.avi   a trial: a folder with its video(s)
  myproject/session1/trial01/config.toml  optional: keys that differ in this trial

Outputs go beside each video (walk.detections.npz, walk.results.csv + .json, .png with
[fit] plot); myproject/summary.csv lists every trial (state, frames, median error, % bad
frames, time, message, warnings) and myproject/logs/ holds one log per run that did
something. Trials whose outputs are up to date (same content of the videos and files, same
parameters) are skipped; an interrupted fit resumes where it stopped. Outputs never replace
an input, nor (without --force) an existing file of another kind.

exit status: 0 every trial is done or up to date (warnings are listed, not errors);
1 a trial failed (the others still ran), or bad arguments; 3 no trial failed but one is
incomplete (a video or image could not be read to the end, not one frame was fitted, or
more than half the frames failed), unless --allow-incomplete. A trial whose set-up the checks
refuse (views that disagree in 3D, a chain that does not fit) fails with the cause; set
[anneal] accept_setup = true in its config to fit it anyway.
"""


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "batch",
        help="detect and fit every trial of a project folder (resumable, parallel, Dask)",
        description=(
            "Find every trial of a project folder (its config.toml files are inherited "
            "down the tree), detect markers and fit the chain in each, skipping what is up "
            "to date, and write a summary table. Trials run in parallel on this machine "
            "(--jobs) or as tasks of a Dask cluster (--scheduler); results are the same "
            "either way. A failing trial is reported and the others go on."
        ),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("project", type=Path, help="project folder (holding config.toml)")
    p.add_argument("--trial", "-t", action="append", default=[], metavar="PATTERN",
                   help="only trials whose names (e.g. session1/trial01) match this glob "
                        "pattern (repeatable)")
    p.add_argument("--jobs", "-j", type=int, metavar="N",
                   help="trials at a time, one process each (default: [batch] jobs, else "
                        "one per core); each gets cores/N fitting threads; 1: one trial "
                        "after the other in this process, on every core")
    p.add_argument("--force", action="store_true",
                   help="recompute although the outputs are up to date")
    p.add_argument("--dry-run", "-n", action="store_true",
                   help="list what would run and why; write nothing")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the trials on this Dask cluster: tcp://host:port or a "
                        "scheduler file (JSON)")
    p.add_argument("--allow-incomplete", action="store_true",
                   help="exit 0 although a trial is incomplete (its video could not be read "
                        "to the end, no frame was fitted, or most frames failed); it is "
                        "still listed")
    p.set_defaults(func=run)


def run(args) -> int:
    from tqdm import tqdm

    from videotrack.batch import (
        FAILED,
        INCOMPLETE,
        RunLog,
        available_cores,
        count_states,
        format_summary,
        nothing_ran,
        plan_trial,
        project_inputs,
        project_lock,
        run_batch,
        write_summary,
    )
    from videotrack.commands._common import EXIT_INCOMPLETE
    from videotrack.errors import VideoTrackError
    from videotrack.project.folders import open_project
    from videotrack.project.outputs import guard_outputs
    from videotrack.results.tables import text_table

    if args.jobs is not None and args.jobs < 0:
        raise VideoTrackError("must be at least 0 (0: one per core)", field="--jobs")
    project = open_project(args.project)
    trials = project.select(args.trial)
    cores = available_cores()
    jobs = args.jobs if args.jobs is not None else project.batch["jobs"]
    jobs = min(jobs or cores, len(trials))
    if args.dry_run:
        rows = []
        for trial in tqdm(trials, desc="checking", unit="trial", leave=False, file=sys.stderr,
                          disable=None):
            rows.append((trial.name, *plan_trial(trial, args.force)))
        table = text_table(("trial", "action", "why"), rows, left=3)
        print("\n".join(line.rstrip() for line in table.splitlines()))
        work = sum(r[1] not in ("up to date", "fails") for r in rows)
        print(f"{len(rows)} trials: {work} to process, "
              f"{sum(r[1] == 'up to date' for r in rows)} up to date, "
              f"{sum(r[1] == 'fails' for r in rows)} failing (dry run: nothing written)")
        for folder, why in project.ignored:
            print(f"not a trial: {folder.relative_to(project.root).as_posix()} ({why})")
        return 0

    guard_outputs({project.summary_path: "summary"}, project_inputs(project.trials),
                  force=args.force, field="batch.summary")
    with project_lock(project):
        log = RunLog(project)
        try:
            where = (f"Dask cluster {args.scheduler}" if args.scheduler else
                     f"{jobs} process(es) x {max(1, cores // jobs)} thread(s)" if jobs > 1
                     else f"this process, {cores} thread(s)")
            log.write(f"command: videotrack {' '.join(sys.argv[1:])}")
            log.write(f"project {project.root}: {len(trials)} trial(s) on {where}"
                      f"{', --force' if args.force else ''}")
            for folder, why in project.ignored:
                log.write(f"not a trial: {folder.relative_to(project.root).as_posix()} ({why})")
            with tqdm(total=len(trials), desc="trials", unit="trial", file=sys.stderr,
                      position=0, disable=None) as trial_bar, \
                    tqdm(total=0, desc="frames", unit="frame", file=sys.stderr, position=1,
                         leave=False, disable=None) as frame_bar:
                def on_report(report) -> None:
                    log.report(report)
                    for warning in report.warnings:
                        tqdm.write(f"videotrack: warning: {report.name}: {warning}",
                                   file=sys.stderr)
                    if report.state == FAILED:
                        tqdm.write(f"videotrack: {report.name} failed: {report.message}",
                                   file=sys.stderr)
                    trial_bar.update(1)

                def on_frames(done: int, total: int) -> None:
                    if total:
                        frame_bar.total += total
                        frame_bar.refresh()
                    frame_bar.update(done)

                reports = run_batch(trials, force=args.force, jobs=jobs,
                                    scheduler=args.scheduler, on_report=on_report,
                                    progress=on_frames)
            names = [t.name for t in project.trials]  # --trial: the others' rows stay
            summary = None  # read-only storage and nothing to do: nothing written
            if not (nothing_ran(reports) and not os.access(project.root, os.W_OK)):
                summary = write_summary(reports, project.summary_path, keep=names,
                                        order=names)
            log.write(f"finished: {count_states(reports)}; summary {summary}")
        except KeyboardInterrupt:
            log.write("interrupted: run the same command again to go on")
            log.close()
            raise
        except BaseException:
            log.close()
            raise
        if nothing_ran(reports):  # nothing happened: no log to keep
            log.discard()
            where = "no log (nothing to do)"
        else:
            log.close()
            where = f"log {log.path}"
    print(format_summary(reports))
    wrote = f"wrote {summary}" if summary is not None else "no summary (read-only storage)"
    print(f"{len(reports)} trials: {count_states(reports)}; {wrote}; {where}")
    if log.failed is not None and not nothing_ran(reports):
        print(f"videotrack: warning: {log.path}: the log is incomplete: {log.failed}",
              file=sys.stderr)
    if any(r.state == FAILED for r in reports):
        return 1
    if any(r.state == INCOMPLETE for r in reports) and not args.allow_incomplete:
        print(f"videotrack: {sum(r.state == INCOMPLETE for r in reports)} trial(s) "
              "incomplete (exit status 3; --allow-incomplete accepts them)", file=sys.stderr)
        return EXIT_INCOMPLETE
    return 0
