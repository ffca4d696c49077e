"""`imu-emulator batch`: Monte Carlo realizations of a scene on local worker processes or a Dask cluster."""
from __future__ import annotations

import os
import sys
import time

from imu_emulator.commands.shared import number


ORDER = 20     # place in `imu-emulator --help`


def register(subparsers) -> None:
    p = subparsers.add_parser("batch", help="Monte Carlo: N realizations of a scene (seeds, drawn parameters) on "
                              "local worker processes or Dask, one Parquet file each and a summary table")
    p.add_argument("scene", help="scene file (TOML)")
    p.add_argument("--runs", required=True, type=number(1, 10_000_000, integer=True), help="realizations")
    p.add_argument("-o", "--output", required=True, help="output directory (created if missing; a rerun skips "
                   "the realizations whose files are there)")
    p.add_argument("--seed", type=number(0, 2 ** 64 - 1, integer=True), default=None,
                   help="root seed S (default: the scene's seed); realization i uses SeedSequence(S).spawn()[i]")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=DIST",
                   help="draw a scene value per realization: uniform(LOW,HIGH) or normal(MEAN,SIGMA), optionally "
                   "with a unit; KEY=DIST sets the value, KEY+=DIST adds the draw to the scene's value, KEY*=DIST "
                   "multiplies it, e.g. 'imu1.mounting_rpy_deg+=normal(0,0.5) deg' (repeatable)")
    p.add_argument("--truth", action="store_true", help="add the truth columns to every file")
    p.add_argument("--only", type=number(0, 10_000_000, integer=True), action="append", default=None,
                   metavar="I", help="run realization I only (repeatable): the same file as in the whole batch")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                       help="an existing Dask scheduler (default: $DASK_SCHEDULER_ADDRESS, else local worker "
                       "processes)")
    where.add_argument("--workers", type=number(0, 4096, integer=True), default=None,
                       help="local worker processes (default: the machine's cores); 0 runs in this process")
    p.add_argument("--dashboard", action="store_true", help="run the local workers on a Dask LocalCluster and serve "
                   "its dashboard (bokeh), printing its link; without it they are a plain process pool, which "
                   "costs less CPU (no scheduler, no event loops)")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.set_defaults(func=cmd_batch)


def cmd_batch(args) -> int:
    from imu_emulator.analysis import batch
    from imu_emulator.commands.shared import load_scene_with_warnings
    from imu_emulator.runtime.progress import bar

    scene = load_scene_with_warnings(args.scene)
    seed = scene.seed if args.seed is None else args.seed
    # the tasks are made (and a --vary checked) before any cluster starts
    tasks = batch.tasks_for(args.scene, args.runs, seed, args.output, vary=args.vary, truth=args.truth,
                            indices=args.only)
    show = not args.quiet and sys.stderr.isatty()
    start = time.monotonic()

    def progress(done, total, failed):
        if show:
            sys.stderr.write("\r" + bar(done, total, time.monotonic() - start, "realizations")
                             + (f", {failed} failed" if failed else "") + "\x1b[K")
            sys.stderr.flush()

    context = _executor(args, tasks[0] if tasks else None)
    with context as executor:
        result = batch.run(args.scene, args.runs, seed, args.output, executor=executor, vary=args.vary,
                           truth=args.truth, indices=args.only, progress=progress)
    if show:
        sys.stderr.write("\n")
    found = sum(row["skipped"] for row in result.rows)
    if not args.quiet:
        preload = context.local.preload_s if context.local is not None else None
        shared = "" if preload is None else f"; kernel loaded in {preload:.2f} s before the workers forked"
        print(f"{len(result.rows) - found} realization(s) computed, {found} found complete, "
              f"{len(result.failures)} failed; summary: {result.summary}{shared}", file=sys.stderr)
    batch.report(result)
    return 0 if result.ok else 1


class _executor:
    """Where the realizations run, closed on exit: None (--workers 0: this process), a Dask client (--scheduler or
    $DASK_SCHEDULER_ADDRESS; a Dask LocalCluster with --dashboard) or a process pool (analysis.batch.
    LocalBatchPool, the default)."""

    def __init__(self, args, warm):
        self.args = args
        self.warm = warm           # a task whose kernel local workers inherit (analysis.batch.LocalBatchPool)
        self.client = self.local = None

    def __enter__(self):
        from imu_emulator.analysis import batch
        from imu_emulator.errors import ImuEmulatorError
        address = self.args.scheduler or (None if self.args.workers is not None
                                          else os.environ.get("DASK_SCHEDULER_ADDRESS"))
        if self.args.workers == 0:
            if self.args.dashboard:
                raise ImuEmulatorError("batch: --dashboard shows Dask worker processes; --workers 0 has none")
            return None
        workers = self.args.workers or os.cpu_count() or 1
        if not address and not self.args.dashboard:
            self.local = batch.LocalBatchPool(workers, warm=self.warm)
            return self.local.__enter__()
        try:
            from distributed import Client
        except ImportError:
            needs = ("--dashboard" if not address else "--scheduler" if self.args.scheduler
                     else "$DASK_SCHEDULER_ADDRESS")
            raise ImuEmulatorError(f"batch: {needs} needs Dask, which is not installed (pip install "
                                   "'imu-emulator[batch]'); the default local workers need none") from None
        if address:
            self.client = Client(address)
        else:
            self.local = batch.LocalBatchCluster(workers, dashboard=True, warm=self.warm)
            self.client = self.local.__enter__()
        if not self.args.quiet:
            print(f"dask dashboard: {self.client.dashboard_link}", file=sys.stderr, flush=True)
        return self.client

    def __exit__(self, *exc):
        if self.local is not None:
            self.local.__exit__(*exc)
        elif self.client is not None:
            self.client.close()
