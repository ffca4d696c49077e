"""Sample clock: frequency error (ppm) and jitter. Sample k is taken at t_k = t0 + k·Δt·(1 + ppm·10⁻⁶) + j_k
(j_k Gaussian, standard deviation `clock_jitter_s`, drawn from the seed) while its time stamp stays the nominal
t0 + k·Δt. Positive ppm: a slow clock, each sample later than its stamp. The motion is continuous, so the kernel
evaluates it exactly at t_k (periodic phases included: frac(C0 + (k + clk)·CS)).

The IMUs of a scene share one motion evaluation per sample, hence one sample clock: every [[imu]] that gives
clock_ppm / clock_jitter_s gives the same values."""
from imu_emulator.effects._record import Effect, Param, Stage
from imu_emulator.errors import SceneError

KEYS = ("imu.clock_ppm", "imu.clock_jitter_s")


def settings(scene) -> tuple[float, float]:
    """(ppm, jitter in s) of the scene's one clock; an error naming the IMU whose clock differs."""
    first = tuple(scene.imus[0].values[k] for k in KEYS)
    for i, imu in enumerate(scene.imus[1:], 1):
        if tuple(imu.values[k] for k in KEYS) != first:
            raise SceneError(f"imu[{i}].clock_ppm: the IMUs of a scene share one sample clock; give imu[0]'s "
                             f"clock_ppm and clock_jitter_s")
    return first


def emit(ctx) -> list[str]:
    ppm, jitter = settings(ctx.scene)
    terms = []
    if ppm:
        terms.append(f"k * {ctx.number(ppm * 1e-6)}")
    if jitter:
        terms.append(f"{ctx.number(jitter * ctx.scene.rate_hz)} * {ctx.normal('jitter')}")
    return [f"clk = {' + '.join(terms)}"] if terms else []


def offsets(scene, seed: int, k0: int, s0: int, n: int):
    """clk for samples k0 .. k0+n-1 (run samples s0 ..), as the kernel computes it (for sampled motion)."""
    import numpy as np

    from imu_emulator.numerics.counter_rng import normals, stream_key
    ppm, jitter = settings(scene)
    out = (k0 + np.arange(n, dtype=np.float64)) * (ppm * 1e-6)
    if jitter:
        out += jitter * scene.rate_hz * normals(np.uint64(stream_key(seed, -1, "clock.jitter")), s0, n)
    return out


EFFECT = Effect(
    name="clock",
    description="sample clock frequency error and jitter: motion at the actual instants, nominal time stamps",
    stage=Stage.NAVIGATION, order=-10, emit=emit, random=True, sample_clock=True,
    params=(Param("clock_ppm", "imu", "ppm", "sample clock frequency error (+: slow clock, late samples)",
                  shape="scalar", datasheet="`50` (ppm), `\"0.005 %\"`"),
            Param("clock_jitter_s", "imu", "s", "sample instant jitter, standard deviation", shape="scalar",
                  datasheet="`\"2 us\"`")))
