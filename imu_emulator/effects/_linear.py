"""Helpers the deterministic error effects share: a term M·v added to a triad, read from the true
sensor-frame values (tfx.., twx..), so that several such effects add up to (I + M)·v whatever their order."""
from imu_emulator.effects._record import AXES

#: the true sensor-frame values of each source triad (kernel STAGE_CONTRACT, sensor stage)
TRUE = {"accel": ("tfx", "tfy", "tfz"), "gyro": ("twx", "twy", "twz")}


def add_matrix(out: str, matrix, source: str) -> list[str]:
    """Lines `<out>x += M[0][0] * tfx + ...` for the nonzero elements of M (source: "accel" or "gyro")."""
    lines = []
    for row in range(3):
        terms = [f"{float(matrix[row][col])!r} * {TRUE[source][col]}" for col in range(3) if matrix[row][col]]
        if terms:
            lines.append(f"{out}{AXES[row]} += " + " + ".join(terms))
    return lines
