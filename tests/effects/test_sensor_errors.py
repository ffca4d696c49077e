"""Stochastic sensor errors against the exact statistics of their discrete processes and against allantools.

Tolerances: 5 standard deviations of the estimator used, derived in each test's comment (specs/sensor-errors.md,
"How precisely a test can know an Allan deviation"). Seeds are fixed, so a test is deterministic; the 5-sigma
bound is what keeps it honest for any seed.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_emulator.numerics.counter_rng import normals, stream_key
from imu_emulator.runtime.simulation import Simulation
from tests.support.scenes import scene

G0 = 9.80665
SEEDS = (1, 2, 3)


def static_scene(rate_hz, duration_s, effects, gyro=None, accel=None, seed=1, n_imu=1):
    imus = [{"name": f"imu{i}", "gyro": dict(gyro or {}), "accel": dict(accel or {})} for i in range(n_imu)]
    return scene(rate_hz=rate_hz, duration_s=duration_s, seed=seed, imus=imus, effects=("gravity", *effects))


def errors(scene, truth=False):
    """Gyro and accelerometer errors (output minus the exact static values), (n_imu, n, 3) each."""
    out = Simulation(scene, attitude=False, truth=truth).run()
    return out.gyro, out.accel - np.array([0.0, 0.0, G0]), out


# --- the generator of normals -----------------------------------------------------------------------

def test_counter_normals_are_standard_normal():
    from scipy import stats
    x = normals(np.uint64(stream_key(7, 0, "test")), 0, 1_000_000)
    # mean: sd 1/sqrt(n) = 1e-3; variance: sd sqrt(2/n) = 1.4e-3; KS at the 1e-4 level
    assert abs(x.mean()) < 5e-3 and abs(x.var() - 1) < 5 * math.sqrt(2 / x.size)
    assert stats.kstest(x, "norm").pvalue > 1e-4
    # the tail beyond the ziggurat's base (R = 3.654) is drawn by its own path: its frequency is right
    tail = np.mean(np.abs(x) > 3.6541528853610088)
    p = 2 * stats.norm.sf(3.6541528853610088)
    assert abs(tail - p) < 5 * math.sqrt(p / x.size)


def test_counter_normals_are_a_pure_function_of_key_and_counter():
    key = np.uint64(stream_key(7, 0, "test"))
    whole = normals(key, 0, 1000)
    np.testing.assert_array_equal(np.concatenate([normals(key, k, 7) for k in range(0, 1001, 7)])[:1000], whole)



def test_counter_hash_is_splitmix64():
    # Rosetta Code, "Pseudo-random numbers/Splitmix64": the first five outputs for seed 1234567. Output i of
    # SplitMix64 is the mix of seed + i * gamma, which is normal()'s hash of counter i - 1 under key = seed.
    from imu_emulator.numerics.counter_rng import _GAMMA, mix64
    published = [6457827717110365317, 3203168211198807973, 9817491932198370423, 4593380528125082431,
                 16408922859458223821]
    assert [int(mix64(np.uint64((1234567 + i * int(_GAMMA)) % 2 ** 64))) for i in range(1, 6)] == published


def _ziggurat_draw(key: int, counter: int) -> tuple[float, bool]:
    """normal(key, counter) written out in Python integers from counter_rng's description (Marsaglia & Tsang's
    ziggurat on SplitMix64 bits; the tables are the module's), and whether it left the fast path."""
    from imu_emulator.numerics import counter_rng as rng
    mask, gamma, extra = 2 ** 64 - 1, int(rng._GAMMA), int(rng._EXTRA)

    def mix(z):
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
        return z ^ (z >> 31)

    def unit(i):
        return (mix((z + i * extra) & mask) >> 11) / 2.0 ** 53

    def layer(r):
        idx, r = r & 0xFF, r >> 8
        rabs = (r >> 1) & (2 ** 52 - 1)
        x = float(rabs) * float(rng.WI[idx])
        return idx, rabs, -x if r & 1 else x

    z = (key + (counter + 1) * gamma) & mask
    idx, rabs, x = layer(mix(z))
    i = 1
    if rabs < int(rng.KI[idx]):
        return x, False
    while True:
        if idx == 0:
            while True:
                xx = -math.log1p(-unit(i)) / rng._R
                yy = -math.log1p(-unit(i + 1))
                i += 2
                if yy + yy > xx * xx:
                    return (-(rng._R + xx) if (rabs >> 8) & 1 else rng._R + xx), True
        if (rng.FI[idx - 1] - rng.FI[idx]) * unit(i) + rng.FI[idx] < math.exp(-0.5 * x * x):
            return x, True
        idx, rabs, x = layer(mix((z + (i + 1) * extra) & mask))
        i += 2
        if rabs < int(rng.KI[idx]):
            return x, True


def test_counter_normals_match_the_ziggurat_written_out():
    # the compiled draw against the algorithm in plain Python, bit for bit, over enough draws that the wedge, the tail and the redraws all occur
    key, n = stream_key(7, 0, "test"), 40_000
    reference = [_ziggurat_draw(key, c) for c in range(n)]
    np.testing.assert_array_equal(normals(np.uint64(key), 0, n), [x for x, _ in reference])
    slow = [x for x, rare in reference if rare]
    assert len(slow) > 100 and any(abs(x) > 3.6541528853610088 for x in slow)


def test_kernel_noise_is_the_streams_normals():
    # the generated kernel's per-sample draws are the normals() of the noise streams
    gyro, accel, _ = errors(static_scene(1000, 20.0, ["noise"], {"noise_density": 0.01}, {"noise_density": 0.002}))
    for err, sensor in ((gyro[0], "gyro"), (accel[0], "accel")):
        for axis, name in enumerate("xyz"):
            x = normals(np.uint64(stream_key(1, 0, f"noise.{sensor}.{name}")), 0, err.shape[0])
            # one scale per axis (density times sqrt(rate)); the error is scale * x up to the rounding of the
            # product and of g's subtraction (an ulp of g, 2e-15 m/s^2), where a wrong draw is off by ~0.01
            scale = np.median(err[:, axis] / x)
            np.testing.assert_allclose(err[:, axis], scale * x, rtol=1e-12, atol=1e-13)

# --- exact discrete statistics (fast) --------------------------------------------------------------

@pytest.mark.parametrize("seed", SEEDS)
def test_white_noise_variance_is_density_squared_times_rate(seed):
    nd_g, nd_a = 0.01, 0.002
    gyro, accel, _ = errors(static_scene(1000, 100.0, ["noise"], {"noise_density": nd_g},
                                         {"noise_density": nd_a}, seed=seed))
    n = gyro.shape[1]
    for err, nd in ((gyro[0], nd_g), (accel[0], nd_a)):
        # sample variance of n normals: relative sd sqrt(2/n) = 0.45 % for n = 1e5
        np.testing.assert_allclose(err.var(axis=0) / (nd ** 2 * 1000), 1.0, atol=5 * math.sqrt(2 / n))
        assert np.all(np.abs(err.mean(axis=0)) < 5 * nd * math.sqrt(1000 / n))


def test_datasheet_noise_forms_give_the_same_process():
    a = errors(static_scene(200, 5.0, ["noise"], {"noise_density": "0.007 deg/s/sqrt(Hz)"}))[0]
    b = errors(static_scene(200, 5.0, ["noise"], {"arw": "0.42 deg/sqrt(h)"}))[0]
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=0)


@pytest.mark.parametrize("seed", SEEDS)
def test_random_walk_increment_variance_is_k_squared_dt(seed):
    k_g, k_a, rate = 1e-3, 5e-4, 500
    gyro, accel, _ = errors(static_scene(rate, 200.0, ["random_walk"], {"random_walk": k_g},
                                         {"random_walk": k_a}, seed=seed))
    assert np.all(gyro[0, 0] == 0.0) and np.all(np.abs(accel[0, 0]) < 1e-15)   # the walk starts at 0
    for err, k in ((gyro[0], k_g), (accel[0], k_a)):
        inc = np.diff(err, axis=0)
        # increments are iid N(0, K^2 dt): variance relative sd sqrt(2/n)
        np.testing.assert_allclose(inc.var(axis=0) / (k * k / rate), 1.0, atol=5 * math.sqrt(2 / inc.shape[0]))


def _ar1_checks(x, rho, sigma):
    """x: (n, 3) samples of a stationary AR(1) with lag-1 correlation rho and variance sigma^2.
    Estimator sds (Bartlett / large-n AR(1) results): lag-1 autocorrelation sqrt((1 - rho^2) / n);
    sample variance, relative sqrt(2 (1 + rho^2) / ((1 - rho^2) n))."""
    n = x.shape[0]
    for axis in range(3):
        v = x[:, axis] - x[:, axis].mean()
        r1 = np.dot(v[:-1], v[1:]) / np.dot(v, v)
        assert abs(r1 - rho) < 5 * math.sqrt((1 - rho * rho) / n), (axis, r1, rho)
        rel = math.sqrt(2 * (1 + rho * rho) / ((1 - rho * rho) * n))
        assert abs(v.var() / sigma ** 2 - 1) < 5 * rel, (axis, v.var(), sigma ** 2)


@pytest.mark.parametrize("seed", SEEDS)
def test_gauss_markov_per_sample_lag1_and_stationary_variance(seed):
    sigma, tau, rate = 0.02, 0.05, 1000       # tau < 100 dt: steps every sample
    gyro, _, _ = errors(static_scene(rate, 300.0, ["bias_instability"],
                                     {"gauss_markov_sigma": sigma, "gauss_markov_tau_s": tau}, seed=seed))
    _ar1_checks(gyro[0], math.exp(-1 / (rate * tau)), sigma)


@pytest.mark.parametrize("seed", SEEDS)
def test_gauss_markov_slow_pole_steps_exactly_at_its_knots(seed):
    sigma, tau, rate = 0.5, 2.0, 1000        # m = 20 samples between knots; h = 0.02 s
    _, accel, _ = errors(static_scene(rate, 1000.0, ["bias_instability"], None,
                                      {"gauss_markov_sigma": sigma, "gauss_markov_tau_s": tau}, seed=seed))
    m = int(tau * rate / 100)
    knots = accel[0, ::m]
    _ar1_checks(knots, math.exp(-m / (rate * tau)), sigma)
    # between knots the value is the straight line between them
    i = np.arange(accel.shape[1] - m)
    frac = (i % m) / m
    base = i - i % m
    np.testing.assert_allclose(accel[0, i], accel[0, base] + (accel[0, base + m] - accel[0, base]) * frac[:, None],
                               rtol=0, atol=1e-14)


def test_gauss_markov_starts_stationary():
    """x0 ~ N(0, sigma^2) across seeds: not 0 (gnss-ins-sim), not +sigma (NaveGo). 400 seeds: mean sd
    sigma/20, variance relative sd sqrt(2/400) = 7 %."""
    sigma = 0.3
    first = []
    base = static_scene(100, 0.01, ["bias_instability"], {"gauss_markov_sigma": sigma, "gauss_markov_tau_s": 5.0})
    for seed in range(400):
        import dataclasses
        sim = Simulation(dataclasses.replace(base, seed=seed), attitude=False)
        first.append(sim.block(0, 1).gyro[0, 0])
    first = np.array(first)
    assert np.all(np.abs(first.mean(axis=0)) < 5 * sigma / 20)
    assert np.all(np.abs(first.var(axis=0) / sigma ** 2 - 1) < 5 * math.sqrt(2 / 400))


def test_bias_constant_and_turn_on():
    import dataclasses
    b = [0.01, -0.02, 0.03]
    scene = static_scene(100, 2.0, ["bias"], {"bias": b, "turn_on_bias_sd": 0.05}, {"bias": "20 mg"})
    gyro, accel, out = errors(scene, truth=True)
    # the turn-on part is drawn once per run: constant over the run
    assert np.all(gyro[0] == gyro[0, :1])
    np.testing.assert_allclose(accel[0], 20e-3 * G0, rtol=1e-12)
    np.testing.assert_array_equal(out.truth["gyro_bias"][0], gyro[0])
    draws = []
    for seed in range(400):
        g = Simulation(dataclasses.replace(scene, seed=seed), attitude=False).block(0, 1).gyro[0, 0]
        draws.append(g - b)
    draws = np.array(draws)
    # mean sd 0.05/20, variance relative sd sqrt(2/400)
    assert np.all(np.abs(draws.mean(axis=0)) < 5 * 0.05 / 20)
    assert np.all(np.abs(draws.var(axis=0) / 0.05 ** 2 - 1) < 5 * math.sqrt(2 / 400))


# --- reproducibility --------------------------------------------------------------------------------

FULL_GYRO = {"noise_density": "0.007 deg/s/sqrt(Hz)", "bias_instability": "10 deg/h", "random_walk": "0.5 deg/h/sqrt(h)",
             "bias": ["0.1 deg/s", 0, 0], "turn_on_bias_sd": "0.2 deg/s", "gauss_markov_sigma": "0.01 deg/s",
             "gauss_markov_tau_s": 0.3}
FULL_ACCEL = {"noise_density": "120 ug/sqrt(Hz)", "bias_instability": "30 ug", "random_walk": 1e-4}
ERRORS = ["noise", "bias_instability", "random_walk", "bias"]


def test_same_seed_same_bytes_whatever_the_block_size():
    scene = static_scene(1000, 3.0, ERRORS, FULL_GYRO, FULL_ACCEL, seed=42, n_imu=2)
    whole = Simulation(scene, attitude=False).run()
    for size in (1, 7, 1000):
        sim = Simulation(scene, attitude=False)
        blocks = [sim.block(k, min(size, scene.n_samples - k)) for k in range(0, scene.n_samples, size)]
        np.testing.assert_array_equal(np.concatenate([b.gyro for b in blocks], axis=1), whole.gyro)
        np.testing.assert_array_equal(np.concatenate([b.accel for b in blocks], axis=1), whole.accel)


def test_out_of_order_blocks_replay_to_the_same_values():
    scene = static_scene(1000, 3.0, ERRORS, FULL_GYRO, FULL_ACCEL, seed=42)
    whole = Simulation(scene, attitude=False).run()
    sim = Simulation(scene, attitude=False)
    late = sim.block(2000, 500)          # forward jump: replays 0..1999
    early = sim.block(100, 50)           # backward: restarts from the run's start
    np.testing.assert_array_equal(late.gyro, whole.gyro[:, 2000:2500])
    np.testing.assert_array_equal(early.accel, whole.accel[:, 100:150])


def test_seeds_and_imus_are_independent():
    n_g = 0.01
    a = errors(static_scene(1000, 50.0, ERRORS, {"noise_density": n_g}, seed=1, n_imu=2))[0]
    b = errors(static_scene(1000, 50.0, ERRORS, {"noise_density": n_g}, seed=2, n_imu=2))[0]
    n = a.shape[1]
    pairs = [(a[0], b[0]), (a[0], a[1]), (b[0], b[1])]
    for x, y in pairs:
        for axis in range(3):
            # correlation of independent series: sd 1/sqrt(n)
            assert abs(np.corrcoef(x[:, axis], y[:, axis])[0, 1]) < 5 / math.sqrt(n)
    # axes of one IMU are independent too
    assert abs(np.corrcoef(a[0, :, 0], a[0, :, 1])[0, 1]) < 5 / math.sqrt(n)


def test_a_looped_run_does_not_repeat_its_noise():
    scene = static_scene(1000, 2.0, ["noise"], {"noise_density": 0.01})
    sim = Simulation(scene, attitude=False)
    first = sim.block(0, 2000).gyro[0]
    second = sim.block(0, 2000, run_sample=2000).gyro[0]   # the second pass of a looped stream
    assert abs(np.corrcoef(first[:, 0], second[:, 0])[0, 1]) < 5 / math.sqrt(2000)
    # and it is the run's own samples 2000..3999, as an unlooped longer run has them
    longer = Simulation(static_scene(1000, 4.0, ["noise"], {"noise_density": 0.01}), attitude=False).run()
    np.testing.assert_array_equal(second, longer.gyro[0, 2000:])


def test_generate_in_another_process_gives_the_same_bytes(tmp_path):
    import subprocess
    import sys
    path = tmp_path / "s.toml"
    path.write_text("""
[scene]
rate_hz = 500
duration_s = 4.0
seed = 9
[trajectory]
shape = "circle"
radius_m = 2.0
frequency_hz = 0.5
[attitude]
mode = "tangent"
[[imu]]
name = "a"
lever_arm_m = [0.1, 0.0, 0.0]
[imu.gyro]
noise_density = "0.007 deg/s/sqrt(Hz)"
bias_instability = "10 deg/h"
random_walk = "0.5 deg/h/sqrt(h)"
[imu.accel]
noise_density = "120 ug/sqrt(Hz)"
turn_on_bias_sd = "5 mg"
[effects]
gravity = true
lever_arm = true
noise = true
bias_instability = true
random_walk = true
bias = true
""")
    from imu_emulator import load_scene
    here = Simulation(load_scene(path), attitude=False).run()
    for block in ("7", "100000"):
        out = tmp_path / f"o{block}.npz"
        subprocess.run([sys.executable, "-m", "imu_emulator", "generate", str(path), "-o", str(out), "--quiet",
                        "--block", block], check=True)
        data = np.load(out)
        np.testing.assert_array_equal(data["gyro"], here.gyro)
        np.testing.assert_array_equal(data["accel"], here.accel)


def test_truth_reports_the_realized_bias():
    scene = static_scene(200, 20.0, ERRORS, FULL_GYRO, FULL_ACCEL, seed=5)
    gyro, accel, out = errors(scene, truth=True)
    no_noise = static_scene(200, 20.0, ["bias_instability", "random_walk", "bias"], FULL_GYRO,
                            {k: v for k, v in FULL_ACCEL.items() if k != "noise_density"}, seed=5)
    g2, a2, _ = errors(no_noise)
    # the bias streams do not depend on whether noise is on, and truth is exactly the output without noise
    np.testing.assert_allclose(out.truth["gyro_bias"][0], g2[0], rtol=0, atol=1e-15)
    # accel z carries g: (g + b) - g is exact only to an ulp of 9.8 (1.8e-15)
    np.testing.assert_allclose(out.truth["accel_bias"][0], a2[0], rtol=0, atol=4e-15)


def test_stream_to_file_gives_generate_bytes_and_a_loop_continues_the_noise(tmp_path):
    """`stream --loop` to a capture file (pymavlink decodes it) carries, for run sample j, exactly the float32
    of the sample j of one longer unlooped run: the noise follows the run, the motion the scene."""
    from tests.support.stream import mavlink_parse, run_emulator
    from imu_emulator import load_scene
    scene_text = """
[scene]
rate_hz = 200
duration_s = 0.5
seed = 3
[trajectory]
shape = "static"
[[imu]]
name = "imu0"
[imu.gyro]
noise_density = 0.01
bias_instability = 0.002
random_walk = 0.001
[imu.accel]
noise_density = 0.02
[effects]
gravity = true
noise = true
bias_instability = true
random_walk = true
"""
    path = tmp_path / "s.toml"
    path.write_text(scene_text)
    longer = tmp_path / "long.toml"
    longer.write_text(scene_text.replace("duration_s = 0.5", "duration_s = 1.25"))
    out = tmp_path / "out.bin"
    result = run_emulator(str(path), "--format", "mavlink-highres", "--to", f"file:{out}", "--loop", "--count", "250",
                          "--speed", "0", "--quiet")
    assert result.returncode == 0, result.stderr
    messages, bad = mavlink_parse(out.read_bytes())
    assert len(messages) == 250 and not bad
    reference = Simulation(load_scene(longer), attitude=False).run()
    # The wire is forward-right-down: the ENU scene's forward-left-up y and z change sign (README conventions)
    frd = np.array([1.0, -1.0, -1.0])
    got = np.array([[m.xgyro, m.ygyro, m.zgyro] for m in messages])
    np.testing.assert_array_equal(got, (reference.gyro[0] * frd).astype(np.float32))
    got = np.array([[m.xacc, m.yacc, m.zacc] for m in messages])
    np.testing.assert_array_equal(got, (reference.accel[0] * frd).astype(np.float32))


@pytest.mark.parametrize("table, key, value", [("gyro", "noise_density", "5 m/s"), ("accel", "bias", "3 deg/s"),
                                               ("gyro", "random_walk", "0.5 deg/h")])
def test_wrong_dimension_in_a_scene_is_one_line_naming_the_key(table, key, value):
    from imu_emulator.errors import SceneError
    with pytest.raises(SceneError, match=rf"^imu\[0\]\.{table}\.{key}: .*wrong dimension") as info:
        static_scene(100, 1.0, ["noise", "bias", "random_walk"], **{table: {key: value}})
    assert "\n" not in str(info.value)


def test_gauss_markov_needs_its_correlation_time():
    from imu_emulator.errors import SceneError
    with pytest.raises(SceneError, match=r"imu\[0\]\.gyro\.gauss_markov_tau_s"):
        static_scene(100, 1.0, ["bias_instability"], {"gauss_markov_sigma": 0.1})
