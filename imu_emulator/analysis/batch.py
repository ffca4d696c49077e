"""Monte Carlo batches: N realizations of a scene, each with its own seed (and drawn --vary parameters), each
written by whoever computes it to DIR/run-NNNNN.parquet, then one summary table (DIR/summary.parquet and .csv).

Realization i is a pure function of (scene file, root seed S, i, --vary): its scene seed is the first 64-bit word
of numpy's SeedSequence(S).spawn(...)[i] (SeedSequence(S, spawn_key=(i,))), its drawn values come from streams
keyed on (S, i, KEY) (imu_emulator.scene.variations), so it is the same alone, in a serial batch or on any worker of any
cluster. Nothing large travels: a task is the parsed scene file and a few numbers, a result is one summary row.

Restart: files appear only complete (imu_emulator.output.atomic), so a file that exists is a finished realization;
a rerun reads its summary statistics back instead of computing it again (after checking its footer records the
same seed and draws). A failed realization is a row with its seed and error; the others go on.

Executors: `executor=None` runs in this process; anything with `submit` (a dask.distributed Client, a
concurrent.futures executor) runs the realizations there. The CLI (imu_emulator.commands.batch) makes the
executor: a Dask client for a given scheduler, a Dask LocalCluster when the dashboard is asked for, else a
process pool (LocalBatchPool).
"""
from __future__ import annotations

import json
import os
import socket
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imu_emulator.errors import ImuEmulatorError

CHANNELS = ("ax", "ay", "az", "gx", "gy", "gz")
SUMMARY_NAME = "summary"


def realization_seed(root_seed: int, index: int) -> int:
    """Scene seed of realization `index`: 64 bits of SeedSequence(root_seed).spawn(index + 1)[index]."""
    return int(np.random.SeedSequence(root_seed, spawn_key=(index,)).generate_state(1, np.uint64)[0])


def run_file(out: Path, index: int) -> Path:
    return Path(out) / f"run-{index:05d}.parquet"


@dataclass(frozen=True)
class Task:
    """What a worker needs for one realization (small: the parsed scene file, not samples)."""
    index: int
    root_seed: int
    raw: dict | None               # the parsed scene file, or None with `scene`
    base_dir: str
    scene_path: str | None
    scene: object | None           # a validated Scene given in code (no --vary then)
    variations: tuple = ()
    out: str = "."
    truth: bool = False
    block: int = 65536

    @property
    def seed(self) -> int:
        return realization_seed(self.root_seed, self.index)

    def drawn(self) -> dict:
        return {v.name: v.draw(self.root_seed, self.index) for v in self.variations}

    def build(self, drawn: dict | None = None):
        """The validated scene of this realization (its seed set, its draws or `drawn` applied)."""
        import dataclasses

        from imu_emulator.scene import variations
        from imu_emulator.scene.load import from_dict
        if self.raw is None:
            return dataclasses.replace(self.scene, seed=self.seed)
        names = [imu.get("name", f"imu{i}") for i, imu in enumerate(_imu_tables(self.raw))]
        raw = variations.apply(self.raw, self.variations, self.drawn() if drawn is None else drawn, names)
        raw.setdefault("scene", {})["seed"] = self.seed
        return from_dict(raw, base_dir=self.base_dir, path=self.scene_path)


def _imu_tables(raw: dict) -> list:
    imus = raw.get("imu", [])
    return [imus] if isinstance(imus, dict) else list(imus)


# --- on the worker -----------------------------------------------------------------------------------------

#: this process's kernel loads: scene key -> seconds the first load (compile or disk cache) took
KERNEL_LOADS: dict[str, float] = {}


def realize(task: Task) -> dict:
    """Compute one realization (or find it done) and return its summary row. Runs on a worker."""
    from imu_emulator.output.formats.parquet import read_metadata
    cpu_start = time.thread_time()
    path = run_file(Path(task.out), task.index)
    identity = {"index": task.index, "seed": task.seed, "batch_seed": task.root_seed, "drawn": task.drawn()}
    row = {**identity, "file": path.name, "worker": f"{socket.gethostname()}:{os.getpid()}",
           "kernel_load_s": None, "skipped": False}
    if path.exists():
        found = read_metadata(path).get("batch", {})
        if ({k: found.get(k) for k in identity} != json.loads(json.dumps(identity))
                or bool(found.get("truth", False)) != task.truth):
            raise ImuEmulatorError(f"{path}: written by another batch (its seed, draws or --truth differ); "
                                   "write this batch to a new directory")
        row["skipped"] = True
    else:
        row["kernel_load_s"] = _write(task, path, identity)
    row["stats"] = summarize(path)
    row["cpu_s"] = time.thread_time() - cpu_start
    return row


def _simulation(scene, truth: bool):
    """The Simulation of `scene`, and the seconds its kernel's first load in this process took (None when this
    process had the kernel: one load per structure and process, counted in KERNEL_LOADS)."""
    from imu_emulator.runtime.cache import scene_key
    from imu_emulator.runtime.kernels import is_loaded
    from imu_emulator.runtime.simulation import Simulation
    key = scene_key(scene, attitude=False, truth=truth)
    loaded_before = is_loaded(scene, attitude=False, truth=truth)
    start = time.perf_counter()
    sim = Simulation(scene, attitude=False, truth=truth)
    load_s = None
    if not loaded_before:
        load_s = KERNEL_LOADS[key] = time.perf_counter() - start
    return sim, load_s


def preload(task: Task) -> float | None:
    """Load the kernel of `task`'s structure (with its own draws: a distribution's middle value may be the zero
    that turns an effect off, another structure) in this process: the driver, before a local cluster forks its
    workers, which then inherit it instead of each loading it. The seconds the load took, None if it was here. A
    scene that fails here fails in its realization."""
    try:
        return _simulation(task.build(), task.truth)[1]
    except ImuEmulatorError:
        return None


def _write(task: Task, path: Path, identity: dict) -> float | None:
    from imu_emulator.output.formats import open_writer
    from imu_emulator.output.formats.parquet import run_metadata
    scene = task.build()
    sim, load_s = _simulation(scene, task.truth)
    from imu_emulator.motion import earth_truth
    from imu_emulator.scene.earth import model_on
    conventions = earth_truth.conventions(scene) if task.truth and model_on(scene) else None   # Earth columns
    from imu_emulator.output.columns import scene_companions
    with open_writer(path, scene.imu_names, task.truth, bias_truth=sim.bias_truth,
                     temperature=sim.temperature, metadata=run_metadata(scene, batch={**identity, "truth": task.truth}),
                     conventions=conventions, companions=scene_companions(scene)) as writer:
        for k0 in range(0, sim.n_samples, task.block):
            writer.write(sim.block(k0, min(task.block, sim.n_samples - k0)))
    return load_s


def summarize(path: Path) -> dict:
    """Mean and standard deviation of each IMU's channels over the run, read back from the file batch by batch
    (bounded memory; partial moments combined as Chan, Golub & LeVeque 1979 do)."""
    import pyarrow.parquet as pq
    parquet = pq.ParquetFile(path)
    moments: dict[str, list] = {}       # imu -> [count, mean (6,), M2 (6,)]
    for batch in parquet.iter_batches(columns=["imu", *CHANNELS]):
        imu = batch.column(0)
        names = np.asarray(imu.dictionary.to_pylist(), dtype=object)
        codes = imu.indices.to_numpy()
        values = np.column_stack([batch.column(i + 1).to_numpy() for i in range(len(CHANNELS))])
        for code in np.unique(codes):
            part = values[codes == code]
            n_b, mean_b = len(part), part.mean(axis=0)
            m2_b = ((part - mean_b) ** 2).sum(axis=0)
            n_a, mean_a, m2_a = moments.get(names[code], (0, np.zeros(len(CHANNELS)), np.zeros(len(CHANNELS))))
            n = n_a + n_b
            delta = mean_b - mean_a
            moments[names[code]] = (n, mean_a + delta * n_b / n, m2_a + m2_b + delta ** 2 * n_a * n_b / n)
    stats = {}
    for name, (n, mean, m2) in moments.items():
        for c, channel in enumerate(CHANNELS):
            stats[f"{name}.{channel}.mean"] = float(mean[c])
            stats[f"{name}.{channel}.std"] = float(np.sqrt(m2[c] / (n - 1))) if n > 1 else 0.0
    return stats


# --- on the driver -----------------------------------------------------------------------------------------

#: Dask settings of the local cluster (issue 25: a one-worker batch cost 2.1x the CPU of --workers 0). Idle, a
#: one-worker cluster with Dask's defaults spent about 33 ms CPU per second in the driver and 32-39 in the worker,
#: with these about 6 and 3 (tools/bench_batch_workers.py --idle): the statistical profiler samples every thread
#: every 10 ms and the system monitor runs twice a second, for a dashboard a batch does not read; the event-loop
#: health tick (20 ms) only feeds "unresponsive" warnings; the memory monitor (100 ms) guards pause/spill/
#: terminate thresholds that a realization, which streams its samples to its file in blocks, stays far below. Set
#: only while the local cluster starts (its workers copy them); a cluster given with --scheduler keeps its own.
LOCAL_DASK_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
}


def fork_workers() -> bool:
    """Whether local workers are forked from the driver (Linux): they inherit its imports (numba, the runtime,
    pyarrow) and its loaded kernel instead of importing and loading them again, which is most of
    what a spawned worker costs. Elsewhere fork is unsafe (macOS) or absent (Windows): Dask's default, spawn."""
    return sys.platform.startswith("linux")


class LocalBatchCluster:
    """A Dask LocalCluster for a batch (the CLI's with --dashboard; LocalBatchPool otherwise), as a context
    manager giving its Client: `workers` single-threaded worker processes (the kernel is single-threaded;
    numba's compile is not something to run twice in one process at once), no dashboard unless asked (it
    imports bokeh and serves a page nobody may open), LOCAL_DASK_CONFIG, and on Linux workers forked after
    `warm` (a Task) has its kernel loaded here, so they share one load. `preload_s`: the seconds that load took
    (None: none was needed or the kernel was here)."""

    def __init__(self, workers: int, dashboard: bool = False, warm: Task | None = None):
        self.workers, self.dashboard, self.warm = workers, dashboard, warm
        self.cluster = self.client = self.preload_s = None

    def __enter__(self):
        import logging

        import dask
        from distributed import Client, LocalCluster
        settings = dict(LOCAL_DASK_CONFIG)
        if fork_workers():
            settings["distributed.worker.multiprocessing-method"] = "fork"
            if self.warm is not None:
                self.preload_s = preload(self.warm)
        with dask.config.set(settings):
            # without the dashboard the scheduler still serves its health routes: on a free local port, not
            # on 8787 with a warning when another cluster has that
            quiet = {} if self.dashboard else {"dashboard": False, "dashboard_address": "127.0.0.1:0"}
            self.cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                        dashboard_address=":8787", scheduler_kwargs=quiet,
                                        silence_logs=logging.ERROR)
            try:
                self.client = Client(self.cluster)
            except BaseException:
                self.cluster.close()
                raise
        return self.client

    def __exit__(self, *exc):
        self.client.close()
        self.cluster.close()


def start_method() -> str:
    """How local workers start: "fork" where fork_workers(), else "spawn"."""
    return "fork" if fork_workers() else "spawn"


class LocalBatchPool:
    """The batch command's local workers without Dask (issue 25: one Dask worker cost 1.35x the CPU of --workers
    0, most of it importing distributed, its scheduler and the event loops' ticks, none of which a batch on one
    machine needs): a concurrent.futures process pool of `workers` processes, started with `method` (default
    start_method()), as a context manager giving the executor. Forked workers start after `warm` (a Task) has
    its kernel loaded here and share that load (`preload_s`, as LocalBatchCluster); spawned ones each load a
    structure's kernel once, on their first realization of it (KERNEL_LOADS). Each worker writes its files; only
    chunks of tasks and summary rows pass through the pipes to and from this process."""

    def __init__(self, workers: int, warm: Task | None = None, method: str | None = None):
        self.workers, self.warm, self.method = workers, warm, method or start_method()
        self.executor = self.preload_s = None

    def __enter__(self):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor
        if self.method == "fork" and self.warm is not None:
            self.preload_s = preload(self.warm)
        self.executor = ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context(self.method))
        return self.executor

    def __exit__(self, exc_type, *exc):
        # after an error or ^C, the chunks not yet started are not started
        self.executor.shutdown(wait=True, cancel_futures=exc_type is not None)



@dataclass
class BatchResult:
    rows: list[dict] = field(default_factory=list)        # one per realization, in index order
    failures: list[dict] = field(default_factory=list)    # index, seed, drawn, error
    summary: Path | None = None

    @property
    def ok(self) -> bool:
        return not self.failures


def load_source(scene):
    """(raw, base_dir, path, scene_object) from a scene file path, a scene dict or a validated Scene; the file
    or dict is validated here once, so a bad scene fails before any task is sent."""
    from imu_emulator.scene.load import from_dict, load_scene
    from imu_emulator.scene.model import Scene
    if isinstance(scene, Scene):
        return None, ".", scene.path, scene
    if isinstance(scene, (str, Path)):
        from imu_emulator.scene.load import tomllib
        validated = load_scene(scene)      # reads and checks the file, errors naming it
        raw = tomllib.loads(Path(scene).read_bytes().decode("utf-8"))
        return raw, str(Path(scene).parent), str(scene), validated
    return dict(scene), ".", None, from_dict(scene)


def tasks_for(scene, n: int, seed: int, out, vary=(), truth: bool = False, indices=None) -> list[Task]:
    """The tasks of a batch; `vary` holds "KEY=DIST" (or +=, *=) texts or Variations. Realization 0's scene is
    built here, so that a --vary naming no usable key fails at once with its one-line error (checked with each
    distribution's middle value: a draw outside what the key accepts fails its own realization only)."""
    from imu_emulator.scene import variations
    raw, base_dir, path, validated = load_source(scene)
    parsed = tuple(v if isinstance(v, variations.Variation) else variations.parse(v, validated, raw)
                   for v in vary)
    keys = [v.key for v in parsed]
    twice = sorted({k for k in keys if keys.count(k) > 1})
    if twice:
        raise variations.VaryError(f"--vary: {twice[0]} is varied twice (one --vary per key)")
    if parsed and raw is None:
        raise variations.VaryError("--vary needs the scene as a file or a dict (it is validated again with the "
                                   "drawn values)")
    if not 0 <= int(seed) < 2 ** 64:
        raise ImuEmulatorError(f"batch seed: expected an integer from 0 to 2**64 - 1, got {seed!r}")
    chosen = range(n) if indices is None else sorted(set(indices))
    bad = [i for i in chosen if not 0 <= i < n]
    if bad:
        raise ImuEmulatorError(f"batch: realization {bad[0]} is not in 0..{n - 1}")
    common = dict(root_seed=int(seed), raw=raw, base_dir=base_dir, scene_path=path,
                  scene=validated if raw is None else None, variations=parsed, out=str(out), truth=truth)
    tasks = [Task(index=i, **common) for i in chosen]
    if parsed and tasks:
        try:
            tasks[0].build({v.name: v.center() for v in parsed})
        except ImuEmulatorError as exc:
            raise variations.VaryError(f"--vary: with each distribution's middle value: {exc}") from None
    return tasks


def run(scene, n: int, seed: int, out, executor=None, vary=(), truth: bool = False, indices=None,
        progress=None) -> BatchResult:
    """Python API: realizations 0..n-1 (or `indices`) of `scene` (a file path, a scene dict or a Scene) with root
    seed `seed`, written to directory `out`; returns the rows and failures and writes the summary table.
    `progress(done, total, failed)` is called as realizations finish."""
    out = Path(out)
    if not out.is_dir():
        try:
            out.mkdir()
        except OSError as exc:
            raise ImuEmulatorError(f"{out}: cannot create the output directory: {exc.strerror or exc}") from None
    tasks = tasks_for(scene, n, seed, out, vary=vary, truth=truth, indices=indices)
    _remove_stale_parts(out)
    result = BatchResult()
    for task, row, error in _execute(tasks, executor):
        if error is None:
            result.rows.append(row)
        else:
            result.failures.append({"index": task.index, "seed": task.seed, "drawn": task.drawn(),
                                    "error": error})
        if progress is not None:
            progress(len(result.rows) + len(result.failures), len(tasks), len(result.failures))
    result.rows.sort(key=lambda r: r["index"])
    result.failures.sort(key=lambda r: r["index"])
    result.summary = write_summary(out, tasks, result)
    return result


def _error_text(exc: BaseException) -> str:
    return str(exc) if isinstance(exc, ImuEmulatorError) else f"{type(exc).__name__}: {exc}"


def realize_chunk(tasks) -> list[tuple[int, dict | None, str | None]]:
    """Several realizations on one worker, one call: (index, row, None) or (index, None, error text) each. A
    chunk costs one round trip to the scheduler instead of one per realization, and the worker keeps its kernel
    between them (one load per structure, KERNEL_LOADS)."""
    out = []
    for task in tasks:
        try:
            out.append((task.index, realize(task), None))
        except Exception as exc:     # one realization's failure is its row, not the chunk's end
            out.append((task.index, None, _error_text(exc)))
    return out


#: realizations per chunk at most: a chunk's results return together, so the progress line moves per chunk
MAX_CHUNK = 16


def chunk_size(n_tasks: int, workers: int) -> int:
    """Realizations per submitted call: about four chunks per worker (a slow chunk at the end waits for no more
    than a quarter of a worker's share), at most MAX_CHUNK."""
    return max(1, min(MAX_CHUNK, n_tasks // (4 * max(1, workers))))


def _worker_count(executor) -> int:
    if _is_dask(executor):
        return len(executor.scheduler_info().get("workers", {})) or 1
    return int(getattr(executor, "_max_workers", 1) or 1)


def _execute(tasks, executor):
    """(task, row, None) or (task, None, error text) for each task, as they finish (in chunks on an executor)."""
    if executor is None:
        for task in tasks:
            try:
                yield task, realize(task), None
            except Exception as exc:     # one realization's failure is its row, not the batch's end
                yield task, None, _error_text(exc)
        return
    size = chunk_size(len(tasks), _worker_count(executor))
    chunks = [tasks[i:i + size] for i in range(0, len(tasks), size)]
    futures = {executor.submit(realize_chunk, chunk, **_submit_options(executor)): chunk for chunk in chunks}
    for future in _as_completed(executor, futures):
        chunk = futures[future]
        by_index = {task.index: task for task in chunk}
        try:
            results = future.result()
        except Exception as exc:     # the worker died or the chunk could not be sent: each of its tasks failed
            for task in chunk:
                yield task, None, _error_text(exc)
            continue
        for index, row, error in results:
            yield by_index[index], row, error


def _is_dask(executor) -> bool:
    return type(executor).__module__.startswith("distributed")


def _submit_options(executor) -> dict:
    # Dask would treat equal calls as one task; each realization is its own (and never retried silently)
    return {"pure": False} if _is_dask(executor) else {}


def _as_completed(executor, futures):
    if _is_dask(executor):
        from distributed import as_completed
        return as_completed(list(futures))
    from concurrent.futures import as_completed
    return as_completed(futures)


def _remove_stale_parts(out: Path) -> None:
    """Temporary files of realizations that were killed mid-write (their writer could not remove them)."""
    for part in out.glob(".run-*.parquet.*.part"):
        try:
            part.unlink()
        except OSError:
            pass


def summary_columns(tasks, result: BatchResult) -> dict:
    """One row per realization: index, seed, status, error, file, the worker that computed it, the seconds its
    first load of the kernel took there (empty when the worker had it), the realization's CPU seconds on the
    worker's thread, each drawn value, summary statistics."""
    by_index = {r["index"]: r for r in result.rows}
    failed = {f["index"]: f for f in result.failures}
    columns: dict[str, list] = {"index": [], "seed": [], "status": [], "error": [], "file": [], "worker": [],
                                "kernel_load_s": [], "cpu_s": []}
    variations = tasks[0].variations if tasks else ()
    for v in variations:
        for j in (range(v.count) if v.count > 1 else [None]):
            columns[v.label(j)] = []
    stat_names = sorted({k for r in result.rows for k in r["stats"]}, key=lambda k: (k.split(".")[0], k))
    for name in stat_names:
        columns[name] = []
    for task in tasks:
        row, failure = by_index.get(task.index), failed.get(task.index)
        columns["index"].append(task.index)
        columns["seed"].append(task.seed)
        columns["status"].append("failed" if failure else ("found" if row["skipped"] else "done"))
        columns["error"].append(failure["error"] if failure else "")
        columns["file"].append("" if failure else row["file"])
        columns["worker"].append("" if failure else row["worker"])
        columns["kernel_load_s"].append(None if failure else row["kernel_load_s"])
        columns["cpu_s"].append(None if failure else row["cpu_s"])
        drawn = (failure or row)["drawn"]
        for v in variations:
            values = drawn[v.name] if v.count > 1 else [drawn[v.name]]
            for j, value in enumerate(values):
                columns[v.label(j if v.count > 1 else None)].append(value)
        for name in stat_names:
            columns[name].append(None if failure else row["stats"].get(name))
    return columns


def write_summary(out: Path, tasks, result: BatchResult) -> Path:
    """DIR/summary.parquet and DIR/summary.csv (the same table), each written atomically."""
    import pyarrow as pa
    import pyarrow.csv as pa_csv
    import pyarrow.parquet as pq

    from imu_emulator.output.atomic import AtomicOutput
    columns = summary_columns(tasks, result)
    columns["seed"] = pa.array(columns["seed"], pa.uint64())     # seeds use all 64 bits
    for name in ("kernel_load_s", "cpu_s"):
        columns[name] = pa.array(columns[name], pa.float64())
    table = pa.table(columns)
    target = out / f"{SUMMARY_NAME}.parquet"
    with AtomicOutput(target, "wb") as file:
        pq.write_table(table, file.file)
    with AtomicOutput(out / f"{SUMMARY_NAME}.csv", "wb") as file:
        pa_csv.write_csv(table, file.file)
    return target


def report(result: BatchResult, file=None) -> None:
    """One `error:` line per failed realization (with its seed, so it can be rerun alone)."""
    for failure in result.failures:
        print(f"error: realization {failure['index']} (seed {failure['seed']}): {failure['error']}",
              file=file or sys.stderr)
