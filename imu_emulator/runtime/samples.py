"""What the kernel hands downstream: a block of samples for every IMU of a scene, plain arrays in SI.

Sample k of a run is at t = t0 + k*dt (k an integer, never accumulated). All IMUs of a scene share one
body motion, so they share k and t; their outputs differ by lever arm and mounting.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class SampleBlock:
    k0: int                 # index of the first sample in the block
    t_s: np.ndarray         # (n,) sample times, seconds on the scene's time base (t0 + k*dt)
    accel: np.ndarray       # (n_imu, n, 3) specific force in each sensor frame, m/s^2
    gyro: np.ndarray        # (n_imu, n, 3) angular rate of each sensor frame, rad/s
    quat: np.ndarray | None # (n_imu, n, 4) attitude sensor->navigation frame, scalar first (w, x, y, z);
                            # None when the simulation was built without attitude output
    truth: dict | None = None   # with truth requested: "position", "velocity" (n, 3) nav frame,
                                # "euler" (n, 3) roll, pitch, yaw of the body, "omega_body", "alpha_body" (n, 3);
                                # with a bias effect on: "accel_bias", "gyro_bias" (n_imu, n, 3), realized
                                # bias of each triad (constant + turn-on + instability + random walk)
    temperature_c: np.ndarray | None = None   # (n_imu, n) each IMU's simulated temperature, degC, with the
                                              # temperature effect on (else None: formats send their default)
    dtheta: np.ndarray | None = None   # (n_imu, n, 3) integral of the gyro's rate over (t_k-1, t_k], rad, and
    dvel: np.ndarray | None = None     # of the specific force, m/s (imu_emulator.codegen.increments); None unless asked
    time_offset_s: np.ndarray | None = None   # (n_imu,) [[imu]] time_offset_s, added to each IMU's stamps in
                                              # every output; None when every IMU's is 0
    companion: list | None = None   # per IMU, {field: (n,) or (n, k)} of the companion sensors it carries
                                    # (imu_emulator.companions: Samples' field names, e.g. "mag", "gnss_llh");
                                    # None when no IMU carries one

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def n_imu(self) -> int:
        return int(self.accel.shape[0])

    def view(self, start: int, stop: int) -> "SampleBlock":
        """Samples start..stop-1 of this block as views (writing to them writes to this block)."""
        return SampleBlock(k0=self.k0 + start, t_s=self.t_s[start:stop], accel=self.accel[:, start:stop],
                           gyro=self.gyro[:, start:stop],
                           quat=None if self.quat is None else self.quat[:, start:stop],
                           truth=None if self.truth is None else {k: _along_samples(v, start, stop)
                                                                  for k, v in self.truth.items()},
                           temperature_c=None if self.temperature_c is None else self.temperature_c[:, start:stop],
                           dtheta=None if self.dtheta is None else self.dtheta[:, start:stop],
                           dvel=None if self.dvel is None else self.dvel[:, start:stop],
                           time_offset_s=self.time_offset_s,
                           companion=None if self.companion is None else [
                               {k: v[start:stop] for k, v in fields.items()} for fields in self.companion])

    def time_ns(self, offset_ns: int = 0) -> np.ndarray:
        """Sample times as integer nanoseconds (exact to the ns for any sane t0), plus an offset."""
        return np.rint(self.t_s * 1e9).astype(np.int64) + np.int64(offset_ns)

    def imu_offset_ns(self, imu: int) -> int:
        """IMU `imu`'s time_offset_s in integer nanoseconds, to add to time_ns()."""
        return 0 if self.time_offset_s is None else int(round(float(self.time_offset_s[imu]) * 1e9))

    def imu_t_s(self) -> np.ndarray:
        """(n_imu, n) each IMU's time stamps in seconds: t_s plus its time_offset_s."""
        offsets = np.zeros(self.n_imu) if self.time_offset_s is None else self.time_offset_s
        return self.t_s[None, :] + offsets[:, None]


def _along_samples(array: np.ndarray, start: int, stop: int) -> np.ndarray:
    return array[start:stop] if array.ndim == 2 else array[:, start:stop]


def concatenate(blocks: list[SampleBlock]) -> SampleBlock:
    first = blocks[0]
    truth = None
    if first.truth is not None:
        # (n, 3) body truth, or (n_imu, n, 3) per-IMU truth (realized biases)
        truth = {k: np.concatenate([b.truth[k] for b in blocks], axis=first.truth[k].ndim - 2) for k in first.truth}
    return SampleBlock(k0=first.k0, t_s=np.concatenate([b.t_s for b in blocks]),
                       accel=np.concatenate([b.accel for b in blocks], axis=1),
                       gyro=np.concatenate([b.gyro for b in blocks], axis=1),
                       quat=None if first.quat is None else np.concatenate([b.quat for b in blocks], axis=1),
                       truth=truth, temperature_c=None if first.temperature_c is None else
                       np.concatenate([b.temperature_c for b in blocks], axis=1),
                       dtheta=None if first.dtheta is None else np.concatenate([b.dtheta for b in blocks], axis=1),
                       dvel=None if first.dvel is None else np.concatenate([b.dvel for b in blocks], axis=1),
                       time_offset_s=first.time_offset_s,
                       companion=None if first.companion is None else [
                           {k: np.concatenate([b.companion[m][k] for b in blocks]) for k in fields}
                           for m, fields in enumerate(first.companion)])


def counts_text(counts: dict[str, dict[str, int]]) -> str:
    """One line for the effects' counters ("range saturation: imu0 gyro.z 120, accel.z 0"), "" when none."""
    parts = {}
    for imu, labels in counts.items():
        for label, n in labels.items():
            effect, _, what = label.partition(".")
            parts.setdefault(effect, []).append(f"{imu} {what} {n}")
    return "; ".join(f"{effect} saturation: " + ", ".join(items) if effect == "range" else
                     f"{effect}: " + ", ".join(items) for effect, items in parts.items())
