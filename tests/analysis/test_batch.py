"""Monte Carlo batches: realization i is the same alone, serially and on any Dask worker; a real multi-process
cluster loads the kernel once per worker; --vary draws follow their distributions and reach the files; a failed
realization is a row, not the end; a killed batch restarts without recomputing what it finished."""
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from imu_emulator.analysis import batch
from imu_emulator.cli import main
from imu_emulator.output.formats.parquet import read_metadata
from tests.support.timing import scaled

SCENE = """
[scene]
rate_hz = 1000
duration_s = {duration}
seed = 3
[trajectory]
shape = "circle"
radius_m = 10.0
frequency_hz = 0.2
[attitude]
mode = "tangent"
[[imu]]
name = "imu0"
gyro = {{ noise_density = "0.01 deg/s/sqrt(Hz)", bias_instability = "3 deg/h" }}
accel = {{ noise_density = "100 ug/sqrt(Hz)" }}
[effects]
gravity = true
noise = true
bias_instability = true
"""
ROOT_SEED = 2026


def _scene(tmp_path, duration=0.5):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE.format(duration=duration))
    return path


def _same_file(a: Path, b: Path) -> bool:
    return pq.read_table(a).equals(pq.read_table(b)) and read_metadata(a) == read_metadata(b)


def test_seeds_are_numpy_seedsequence_spawn():
    # numpy's own spawn as the oracle: child i's first 64-bit word, whatever n is
    children = np.random.SeedSequence(ROOT_SEED).spawn(16)
    for i, child in enumerate(children):
        assert batch.realization_seed(ROOT_SEED, i) == int(child.generate_state(1, np.uint64)[0])


def test_serial_and_two_worker_cluster_give_identical_files(tmp_path):
    from distributed import Client, LocalCluster
    scene = _scene(tmp_path)
    serial = batch.run(scene, 16, ROOT_SEED, tmp_path / "serial")
    assert serial.ok and len(serial.rows) == 16
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \
            Client(cluster) as client:
        parallel = batch.run(scene, 16, ROOT_SEED, tmp_path / "dask", executor=client)
    assert parallel.ok and len({row["worker"] for row in parallel.rows}) == 2
    for i in range(16):
        name = batch.run_file(Path("."), i).name
        assert _same_file(tmp_path / "serial" / name, tmp_path / "dask" / name), name
        assert read_metadata(tmp_path / "dask" / name)["seed"] == batch.realization_seed(ROOT_SEED, i)
    # realization 7 alone (CLI --only) is realization 7 of the batch
    assert main(["batch", str(scene), "--runs", "16", "--seed", str(ROOT_SEED), "--only", "7", "-o",
                 str(tmp_path / "alone"), "--workers", "0", "--quiet"]) == 0
    assert sorted(p.name for p in (tmp_path / "alone").glob("run-*")) == ["run-00007.parquet"]
    assert _same_file(tmp_path / "alone" / "run-00007.parquet", tmp_path / "serial" / "run-00007.parquet")
    # and `generate` of the scene with that seed gives the same samples (another path through the writer)
    text = scene.read_text().replace("seed = 3", f"seed = {batch.realization_seed(ROOT_SEED, 7)}")
    (tmp_path / "seven.toml").write_text(text)
    assert main(["generate", str(tmp_path / "seven.toml"), "-o", str(tmp_path / "seven.parquet"), "--quiet"]) == 0
    assert pq.read_table(tmp_path / "seven.parquet").equals(pq.read_table(tmp_path / "serial" / "run-00007.parquet"))
    # the summary's statistics are those of the file (numpy on the whole column as the oracle)
    summary = pq.read_table(tmp_path / "serial" / "summary.parquet").to_pylist()
    gx = pq.read_table(tmp_path / "serial" / "run-00007.parquet").column("gx").to_numpy()
    assert summary[7]["imu0.gx.mean"] == pytest.approx(gx.mean(), rel=1e-12)
    assert summary[7]["imu0.gx.std"] == pytest.approx(gx.std(ddof=1), rel=1e-12)


def _parent_pid(pid: int) -> int:
    # field 4 of /proc/PID/stat, after the command name in parentheses (which may hold spaces)
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


def _worker_pids(rows) -> set[int]:
    return {int(row["worker"].rsplit(":", 1)[1]) for row in rows}


@pytest.mark.skipif(not batch.fork_workers(), reason="local workers fork only on Linux")
def test_local_workers_fork_with_the_kernel_and_give_the_serial_files(tmp_path, capsys):
    """The CLI's local workers (LocalBatchPool): processes forked from this one after it loaded the kernel, so
    none loads it again (counted: kernel_load_s, and a load asked of a worker finds it there); their files are
    those of --workers 0, with one worker and with two."""
    scene = _scene(tmp_path)
    vary = ["imu0.gyro.noise_density=uniform(0.005,0.02) deg/s/sqrt(Hz)"]
    serial = batch.run(scene, 8, ROOT_SEED, tmp_path / "serial", vary=vary)
    assert serial.ok
    tasks = batch.tasks_for(scene, 8, ROOT_SEED, tmp_path / "two", vary=vary)
    pool = batch.LocalBatchPool(2, warm=tasks[0])
    with pool as executor:
        two = batch.run(scene, 8, ROOT_SEED, tmp_path / "two", executor=executor, vary=vary)
        assert {_parent_pid(pid) for pid in _worker_pids(two.rows)} == {os.getpid()}
        assert executor.submit(batch.preload, tasks[5]).result() is None     # loaded: nothing to do
    assert pool.method == "fork"
    assert two.ok and len(_worker_pids(two.rows)) == 2
    assert [row["kernel_load_s"] for row in two.rows] == [None] * 8
    assert main(["batch", str(scene), "--runs", "8", "--seed", str(ROOT_SEED), "-o", str(tmp_path / "one"),
                 "--workers", "1", "--vary", vary[0]]) == 0
    assert "dask dashboard" not in capsys.readouterr().err           # no dashboard unless --dashboard
    one = pq.read_table(tmp_path / "one" / "summary.parquet").to_pylist()
    assert [r["status"] for r in one] == ["done"] * 8 and len({r["worker"] for r in one}) == 1
    for i in range(8):
        name = batch.run_file(Path("."), i).name
        assert _same_file(tmp_path / "two" / name, tmp_path / "serial" / name), name
        assert _same_file(tmp_path / "one" / name, tmp_path / "serial" / name), name


def _same_batch(a: Path, b: Path, runs: int) -> None:
    """Every run file equal, and the summaries equal but for who computed what and how long it took."""
    for i in range(runs):
        name = batch.run_file(Path("."), i).name
        assert _same_file(a / name, b / name), name
    where = ["worker", "kernel_load_s", "cpu_s"]
    assert (pq.read_table(a / "summary.parquet").drop_columns(where)
            .equals(pq.read_table(b / "summary.parquet").drop_columns(where)))


def test_spawned_local_workers_give_the_in_process_batch(tmp_path, monkeypatch):
    """The start where fork is unsafe or absent (macOS, Windows), forced here: spawned workers import the
    package and each loads the kernel once, on its first realization (this process had the kernel loaded by
    the --workers 0 run: a forked worker would have inherited it and reported no load), and the batch is bit
    for bit the --workers 0 one."""
    monkeypatch.setattr(batch, "fork_workers", lambda: False)
    scene = _scene(tmp_path)
    options = ["batch", str(scene), "--runs", "12", "--seed", str(ROOT_SEED), "--quiet",
               "--vary", "imu0.accel.bias=normal(0,0.05)"]
    assert main([*options, "-o", str(tmp_path / "serial"), "--workers", "0"]) == 0
    assert main([*options, "-o", str(tmp_path / "spawned"), "--workers", "2"]) == 0
    _same_batch(tmp_path / "spawned", tmp_path / "serial", 12)
    rows = pq.read_table(tmp_path / "spawned" / "summary.parquet").to_pylist()
    assert os.getpid() not in _worker_pids(rows)
    for worker in {r["worker"] for r in rows}:
        loads = [r["kernel_load_s"] for r in rows if r["worker"] == worker]
        assert sum(load is not None for load in loads) == 1, (worker, loads)


@pytest.mark.skipif(not batch.fork_workers(), reason="the replaced realize reaches the workers by fork")
def test_a_worker_that_dies_fails_its_realizations_and_none_is_lost(tmp_path, monkeypatch):
    """A local worker killed mid-batch (here: realization 3 ends its process, as the kernel's OOM killer would)
    breaks the pool: every realization is still answered, a row or a failure naming the broken pool, and the
    batch ends instead of waiting for the dead worker."""
    real = batch.realize

    def realize(task):
        if task.index == 3:
            os._exit(9)
        return real(task)
    monkeypatch.setattr(batch, "realize", realize)
    scene = _scene(tmp_path, duration=0.05)
    with batch.LocalBatchPool(2) as executor:
        result = batch.run(scene, 16, ROOT_SEED, tmp_path / "out", executor=executor)
    assert sorted([r["index"] for r in result.rows] + [f["index"] for f in result.failures]) == list(range(16))
    assert 3 in {f["index"] for f in result.failures}
    assert all(f["error"].startswith("BrokenProcessPool: ") for f in result.failures), result.failures
    rows = pq.read_table(tmp_path / "out" / "summary.parquet").to_pylist()
    assert [r["status"] == "failed" for r in rows] == [i in {f["index"] for f in result.failures}
                                                      for i in range(16)]


def test_dashboard_runs_a_dask_local_cluster_with_the_same_batch(tmp_path, capsys):
    """--dashboard keeps Dask for the local workers (its dashboard shows them): the link is printed, the workers
    have the profiler off (LOCAL_DASK_CONFIG), the batch is that of --workers 0; with --workers 0 there is no
    cluster to show, which is refused."""
    scene = _scene(tmp_path)
    options = ["batch", str(scene), "--runs", "6", "--seed", str(ROOT_SEED)]
    assert main([*options, "-o", str(tmp_path / "serial"), "--workers", "0", "--quiet"]) == 0
    assert main([*options, "-o", str(tmp_path / "dask"), "--workers", "2", "--dashboard"]) == 0
    err = capsys.readouterr().err
    assert "dask dashboard: http://" in err, err
    _same_batch(tmp_path / "dask", tmp_path / "serial", 6)
    with batch.LocalBatchCluster(1) as client:
        import dask
        assert set(client.run(dask.config.get, "distributed.worker.profile.enabled").values()) == {False}
    assert main([*options, "-o", str(tmp_path / "none"), "--workers", "0", "--dashboard"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "error: batch: --dashboard shows Dask worker processes; --workers 0 has none", err


def test_local_workers_need_no_dask_and_dask_options_say_they_do(tmp_path, capsys, monkeypatch):
    """Without Dask importable (None in sys.modules: `import distributed` raises ImportError), local workers
    still run the batch; --dashboard and a scheduler address, which need Dask, are refused in one line."""
    monkeypatch.setitem(sys.modules, "distributed", None)
    scene = _scene(tmp_path, duration=0.05)
    options = ["batch", str(scene), "--runs", "3", "--seed", str(ROOT_SEED), "--quiet"]
    assert main([*options, "-o", str(tmp_path / "pool"), "--workers", "2"]) == 0
    assert main([*options, "-o", str(tmp_path / "serial"), "--workers", "0"]) == 0
    _same_batch(tmp_path / "pool", tmp_path / "serial", 3)
    capsys.readouterr()
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", "tcp://127.0.0.1:1")
    for extra, needs in ([], "$DASK_SCHEDULER_ADDRESS"), (["--scheduler", "tcp://127.0.0.1:1"], "--scheduler"), (
            ["--workers", "2", "--dashboard"], "--dashboard"):
        assert main([*options, "-o", str(tmp_path / "x"), *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert err == (f"error: batch: {needs} needs Dask, which is not installed (pip install "
                       "'imu-emulator[batch]'); the default local workers need none"), err


def test_preload_leaves_a_refused_draw_to_its_realization(tmp_path):
    """The load before the workers fork uses realization 0's own draws; when the scene refuses them (a noise
    density below zero: the scene's own check) nothing is loaded and the batch goes on, that realization
    failing alone as it does on any worker."""
    vary = ["imu0.gyro.noise_density=normal(0,1) deg/s/sqrt(Hz)"]
    tasks = batch.tasks_for(_scene(tmp_path), 16, ROOT_SEED, tmp_path / "out", vary=vary)
    refused = next(t for t in tasks if t.drawn()["imu0.gyro.noise_density"] < 0)
    with pytest.raises(batch.ImuEmulatorError, match="noise density is >= 0"):
        refused.build()
    assert batch.preload(refused) is None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_real_scheduler_and_two_worker_processes(tmp_path, kernel_cache):
    """`dask scheduler` and two `dask worker` processes, as a user's cluster would be; each worker loads the
    scene's kernel once for all the realizations it runs."""
    from distributed import Client
    dask = str(Path(sys.executable).with_name("dask"))
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "IMU_EMULATOR_CACHE": str(kernel_cache)}
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for _ in range(2):
            procs.append(subprocess.Popen([dask, "worker", address, "--nworkers", "1", "--nthreads", "1",
                                           "--no-dashboard", "--no-nanny"], env=env,
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with Client(address, timeout=scaled(60)) as client:
            client.wait_for_workers(2, timeout=scaled(120))
            pids = set(client.run(os.getpid).values())
        scene = _scene(tmp_path)
        assert main(["batch", str(scene), "--runs", "12", "--seed", str(ROOT_SEED), "-o", str(tmp_path / "out"),
                     "--scheduler", address, "--quiet"]) == 0
        rows = pq.read_table(tmp_path / "out" / "summary.parquet").to_pylist()
        assert [r["status"] for r in rows] == ["done"] * 12
        workers = {r["worker"] for r in rows}
        assert {int(w.rsplit(":", 1)[1]) for w in workers} == pids        # both worker processes ran tasks
        for worker in workers:
            loads = [r["kernel_load_s"] for r in rows if r["worker"] == worker and r["kernel_load_s"] is not None]
            assert len(loads) == 1, (worker, rows)
        serial = batch.run(scene, 12, ROOT_SEED, tmp_path / "serial")
        assert all(_same_file(tmp_path / "out" / r["file"], tmp_path / "serial" / r["file"]) for r in rows)
    finally:
        for proc in reversed(procs):
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=scaled(20))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def test_vary_draws_follow_their_distributions(tmp_path):
    """Sample mean and variance of 4000 draws within 5 standard errors: SE(mean) = sigma / sqrt(n); SE of the
    sample variance = sqrt((mu4 - sigma^4 (n-3)/(n-1)) / n) (mu4: 4th central moment; normal 3 sigma^4, uniform
    on [a, b] (b-a)^4 / 80)."""
    scene = _scene(tmp_path)
    n = 4000
    tasks = batch.tasks_for(scene, n, ROOT_SEED, tmp_path / "out", vary=[
        "imu0.gyro.bias_instability=uniform(1,5) deg/h", "imu0.mounting_rpy_deg=normal(0.5, 0.25) deg"])
    drawn = [t.drawn() for t in tasks]
    uniform = np.array([d["imu0.gyro.bias_instability"] for d in drawn])
    normal = np.array([d["imu0.mounting_rpy_deg"] for d in drawn])       # (n, 3): three independent draws
    assert normal.shape == (n, 3) and uniform.shape == (n,)
    for values, mean, var, mu4 in [(uniform, 3.0, 16 / 12, 4 ** 4 / 80)] + [
            (normal[:, j], 0.5, 0.25 ** 2, 3 * 0.25 ** 4) for j in range(3)]:
        assert abs(values.mean() - mean) < 5 * np.sqrt(var / n)
        assert abs(values.var(ddof=1) - var) < 5 * np.sqrt((mu4 - var ** 2 * (n - 3) / (n - 1)) / n)
    assert uniform.min() >= 1 and uniform.max() < 5
    # the three angles are not one draw repeated: their sample correlation is that of independent draws
    # (|r| < 5 / sqrt(n))
    assert abs(np.corrcoef(normal[:, 0], normal[:, 1])[0, 1]) < 5 / np.sqrt(n)


def test_vary_values_reach_scene_files_and_summary(tmp_path):
    scene = _scene(tmp_path)
    vary = ["imu0.gyro.bias_instability=uniform(1,5) deg/h"]
    result = batch.run(scene, 2, ROOT_SEED, tmp_path / "out", vary=vary)
    assert result.ok
    summary = pq.read_table(tmp_path / "out" / "summary.parquet").to_pylist()
    for task, row in zip(batch.tasks_for(scene, 2, ROOT_SEED, tmp_path / "x", vary=vary), summary):
        value = task.drawn()["imu0.gyro.bias_instability"]
        assert row["imu0.gyro.bias_instability [deg/h]"] == value
        assert read_metadata(tmp_path / "out" / row["file"])["batch"]["drawn"] == {
            "imu0.gyro.bias_instability": value}
        # the validator turned "x deg/h" into rad/s: x * pi / 180 / 3600 on each axis
        spec = task.build().imus[0].values["imu.gyro.bias_instability"]
        assert spec == pytest.approx((value * np.pi / 180 / 3600,) * 3, rel=1e-15)


@pytest.mark.parametrize("option, message", [
    ("imu9.gyro.bias_instability=uniform(1,5) deg/h", "'imu9' is neither an IMU"),
    ("imu0.gyro.bias_instability=uniform(5,1) deg/h", "LOW < HIGH"),
    ("imu0.gyro.bias_instability=normal(1,0) deg/h", "SIGMA > 0"),
    ("imu0.gyro.bias_instability=gauss(1,2)", "uniform(LOW, HIGH) or normal"),
    ("imu0.gyro.bias_instabilty=uniform(1,5) deg/h", "bias_instabilty: unknown key"),
    ("imu0.gyro.bias_instability=uniform(1,5) m/s", "wrong dimension"),
    ("imu0.gyro.bias_instability=uniform(1,5) parsecs", "not a unit"),
    ("params.f=uniform(1,5) deg", "plain numbers"),
    ("__import__('os').x=uniform(1,2)", "expected KEY=DIST"),
])
def test_bad_vary_is_one_line_exit_2(tmp_path, capsys, option, message):
    scene = _scene(tmp_path)
    assert main(["batch", str(scene), "--runs", "2", "-o", str(tmp_path / "out"), "--workers", "0",
                 "--vary", option]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and message in err, err
    assert not (tmp_path / "out").exists()


def test_failed_realization_is_reported_and_others_finish(tmp_path, capsys):
    scene = _scene(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "run-00002.parquet").mkdir()      # realization 2's file cannot be read or written
    assert main(["batch", str(scene), "--runs", "4", "--seed", str(ROOT_SEED), "-o", str(out), "--workers", "0",
                 "--quiet"]) == 1
    err = capsys.readouterr().err
    assert f"error: realization 2 (seed {batch.realization_seed(ROOT_SEED, 2)}): " in err
    rows = pq.read_table(out / "summary.parquet").to_pylist()
    assert [r["status"] for r in rows] == ["done", "done", "failed", "done"]
    assert rows[2]["seed"] == batch.realization_seed(ROOT_SEED, 2) and rows[2]["error"]


def test_killed_batch_restarts_without_recomputing(tmp_path):
    scene = _scene(tmp_path, duration=2.0)
    out = tmp_path / "out"
    runs = 40
    command = [sys.executable, "-m", "imu_emulator", "batch", str(scene), "--runs", str(runs), "--seed",
               str(ROOT_SEED), "-o", str(out), "--workers", "0", "--quiet"]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + scaled(300)
    while len(list(out.glob("run-*.parquet"))) < 3 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in out.glob("run-*.parquet")}
    assert 3 <= len(before) < runs, len(before)      # killed midway, not before or after
    assert not (out / "summary.parquet").exists()
    assert subprocess.run(command).returncode == 0
    after = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in out.glob("run-*.parquet")}
    assert len(after) == runs and not list(out.glob(".*.part"))
    assert all(after[name] == stamp for name, stamp in before.items())     # not rewritten
    rows = pq.read_table(out / "summary.parquet").to_pylist()
    assert {r["file"] for r in rows if r["status"] == "found"} == set(before)
    assert sum(r["status"] == "done" for r in rows) == runs - len(before)
    # the restarted files are the batch's: realization 39 equals a fresh run of it alone
    alone = batch.run(scene, runs, ROOT_SEED, tmp_path / "alone", indices=[runs - 1])
    assert alone.ok and _same_file(out / "run-00039.parquet", tmp_path / "alone" / "run-00039.parquet")


def test_restart_with_truth_does_not_take_files_written_without_it(tmp_path):
    # A rerun asking for --truth must not skip files that lack the truth columns: it says so instead.
    scene = _scene(tmp_path)
    out = tmp_path / "out"
    assert batch.run(scene, 2, ROOT_SEED, out).ok
    again = batch.run(scene, 2, ROOT_SEED, out, truth=True)
    assert [f["index"] for f in again.failures] == [0, 1]
    assert all("--truth differ" in f["error"] for f in again.failures)
    assert batch.run(scene, 2, ROOT_SEED, out).ok     # the same batch again still restarts cleanly


def test_realizations_go_to_an_executor_in_chunks_each_answered_once(monkeypatch):
    """An executor gets chunks (one submit per chunk, not per realization); every realization comes back once,
    a failing one as its own error while the rest of its chunk goes on, a chunk whose call fails as an error for
    each of its realizations."""
    from concurrent.futures import ThreadPoolExecutor
    from dataclasses import dataclass

    @dataclass(frozen=True)
    class Fake:
        index: int

    def realize(task):
        if task.index == 3:
            raise batch.ImuEmulatorError("drawn value refused")
        return {"index": task.index}
    monkeypatch.setattr(batch, "realize", realize)
    tasks = [Fake(i) for i in range(40)]
    submitted = []

    class Counting(ThreadPoolExecutor):
        def submit(self, fn, *args, **kwargs):
            submitted.append(len(args[0]))
            return super().submit(fn, *args, **kwargs)
    with Counting(max_workers=2) as executor:
        results = list(batch._execute(tasks, executor))
    assert submitted == [batch.chunk_size(40, 2)] * (40 // batch.chunk_size(40, 2)) and submitted[0] == 5
    assert sorted(task.index for task, _, _ in results) == list(range(40))
    assert [(task.index, error) for task, row, error in results if error] == [(3, "drawn value refused")]
    assert all(row == {"index": task.index} for task, row, error in results if not error)

    class Broken(ThreadPoolExecutor):
        def submit(self, fn, *args, **kwargs):
            return super().submit(lambda chunk: 1 / 0, *args)
    with Broken(max_workers=1) as executor:
        results = list(batch._execute(tasks[:8], executor))
    assert sorted(task.index for task, _, _ in results) == list(range(8))
    assert {error for _, _, error in results} == {"ZeroDivisionError: division by zero"}
    assert batch.chunk_size(3, 8) == 1 and batch.chunk_size(10_000, 2) == batch.MAX_CHUNK
