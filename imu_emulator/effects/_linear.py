"""Helpers the deterministic error effects share: a term M·v added to a triad, read from the true
sensor-frame values (tfx.., twx..), so that several such effects add up to (I + M)·v whatever their order."""
from imu_emulator.effects._record import AXES, TRIADS
from imu_emulator.errors import SceneError

#: the true sensor-frame values of each source triad (kernel STAGE_CONTRACT, sensor stage)
TRUE = {"accel": ("tfx", "tfy", "tfz"), "gyro": ("twx", "twy", "twz")}


def add_matrix(ctx, out: str, matrix, source: str) -> list[str]:
    """Lines `<out>x += M[0][0] * tfx + ...` for the nonzero elements of M (source: "accel" or "gyro"), the
    elements run-time parameters (EmitContext.number)."""
    lines = []
    for row in range(3):
        terms = [f"{ctx.number(matrix[row][col])} * {TRUE[source][col]}" for col in range(3) if matrix[row][col]]
        if terms:
            lines.append(f"{out}{AXES[row]} += " + " + ".join(terms))
    return lines


def per_axis(ctx, key: str):
    """(output variable, axis letter, value) for each nonzero value of the triads' parameter `key`."""
    for triad, (_, out, _) in TRIADS.items():
        for axis, value in enumerate(ctx.value(f"imu.{triad}.{key}")):
            if value:
                yield triad, f"{out}{AXES[axis]}", AXES[axis], value


def require_nonnegative(values: dict, key: str, where: str, what: str) -> None:
    """A SceneError naming the key when a triad's `key` is negative on some axis."""
    for triad in TRIADS:
        for axis, value in enumerate(values[f"imu.{triad}.{key}"]):
            if value < 0:
                raise SceneError(f"{where}.{triad}.{key}: {what}, got {value!r} on axis {AXES[axis]}")


def nonnegative(key: str, what: str):
    """The validate function of an effect whose triads' `key` must be >= 0 on every axis (range, resolution)."""
    def validate(values: dict, where: str) -> None:
        require_nonnegative(values, key, where, what)
    return validate
