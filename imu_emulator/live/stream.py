"""One stream: its encoder (or device), its transport and its counters; a block of the simulation becomes the
wire payloads of each sample here."""
from __future__ import annotations

from collections import deque

import numpy as np

import firmware_protocols
from firmware_protocols import attitude
from imu_emulator.geo.geodesy import device_navigation
from imu_emulator.live.config import StreamConfig, StreamError
from imu_emulator.live.ring import Packets
from imu_emulator.live.transport import TARGET_KINDS, check_carries, link_capacity, open_target, parse_target


class Stream:
    def __init__(self, config: StreamConfig, imu_index: int, info, rate_hz: float):
        self.config = config
        self.imu_index = imu_index
        self.info = info
        self.period_s = 1.0 / rate_hz
        self.spec = parse_target(config.target)   # malformed specs fail before anything is opened
        check_carries(self.spec, info.kind)
        self.capacity = link_capacity(self.spec, info.kind, config.target_options)
        self.device = None
        self.navigation = None     # (frame, gravity, origin, model, positions' frame) for navigation
        self.frame = "NED"          # the scene's navigation frame: attitude goes out NED-referenced (run_streams)
        try:
            if config.device and info.device is not None and TARGET_KINDS[self.spec.kind].talks_back:
                # The device encodes too: budgets read its bytes_per_sample / frames_per_sample.
                self.device = self.encoder = info.device(rate_hz, **config.options)
            else:
                self.encoder = firmware_protocols.create_encoder(config.format, **config.options)
        except TypeError as exc:
            known = {**self.info.options, **(self.info.device_options if self.device or config.device else {})}
            raise StreamError(f"{config.format}: bad option ({exc}); known options: "
                              f"{', '.join(known) or 'none'}") from None
        except ValueError as exc:
            raise StreamError(f"{config.format}: {exc}") from None
        self.transport = None
        self.sent = 0
        self.dropped = 0
        self.saturated = 0
        self.idle = 0               # samples for which the device had nothing to send (paused, divided)
        self.replies_sent = 0
        self.replies_delayed = 0    # replies the link refused at first, sent later ahead of the samples
        self.replies_dropped = 0    # replies never sent: the waiting queue was full, or the run ended first
        self._waiting = deque()     # replies the link refused so far, in order; they go before any sample
        self.ignored_input = 0      # bytes or frames that arrived on a link without a device
        self.queue_max = None       # most bytes seen waiting in the link's queue (sampled twice a second)
        self.link = {}              # what the link itself reported, read just before closing it
        self._before = None         # (next k, attitude, increment) of the last sample: see _attitude_change
        self.exact_gyro = False     # the gyro senses the true attitude's rate exactly (run_streams)
        # UTC Unix ns of the unit's power-up: the run's scene time 0 less the link's power-up lead (the streamer
        # sets it before sending)
        self.start_ns = 0

    def power_up_lead_ns(self) -> int:
        """From the unit's power-up to the run's start on this stream's link (Transport.power_up_lead_periods)."""
        return round(self.transport.power_up_lead_periods * self.period_s * 1e9)

    def open(self) -> None:
        self.transport = open_target(self.spec, self.info.kind, self.config.target_options)
        self.transport.sample_period_s = self.period_s

    def samples(self, block, time_ns: np.ndarray):
        """The block's samples of this stream's IMU as every format takes them (firmware_protocols.Samples): the
        part's forward-right-down axes, attitude FRD -> NED, the IMU's own clock. An ENU scene's body is
        forward-left-up: its vectors and attitude are re-expressed here, once (axes.reexpress), so an IMU without
        mounting reads like the real part sitting upright, facing forward, in any scene frame. NED, ECEF and ECI
        scenes already have a forward-right-down body referenced to (local) NED."""
        from firmware_protocols import Samples
        from firmware_protocols.axes import reexpress
        i = self.imu_index
        time_ns = time_ns + block.imu_offset_ns(i)      # the IMU's own clock ([[imu]] time_offset_s)
        # the simulated temperature (temperature effect) for formats that carry one
        temperature = None if block.temperature_c is None else block.temperature_c[i]
        body = "FLU" if self.frame == "ENU" else "FRD"
        # sensor -> navigation in the scene's frame -> sensor -> NED (ECEF and ECI scenes' attitude is w.r.t. local
        # NED already); the body side is turned by reexpress below
        quat = attitude.to_ned(block.quat[i], "ENU" if self.frame == "ENU" else "NED")
        increments = {}
        if block.dtheta is not None:   # over one sample period, by the sensor's own (nominal) clock
            # from the true attitude: the increments are the sensor's, not the unit's estimate's
            increments = {"delta_theta": block.dtheta[i], "delta_velocity": block.dvel[i],
                          "delta_time_s": np.full(len(time_ns), self.period_s),
                          "attitude_change": self._attitude_change(block, quat)}
        if getattr(self.encoder, "true_physics", False):
            companion = {}      # a simulator's physics backend gets the truth, never the unit's own estimate
        else:
            quat, temperature, companion = _companion_fields(block, i, quat, temperature)
        nav = {}
        # imported only when needed: rotations pulls in numba, which every command would pay for at start-up otherwise
        if self.device is not None:
            from imu_emulator.geo.rotations import quat_to_euler
        if self.navigation is not None and block.truth is not None:
            from imu_emulator.geo.rotations import quat_to_matrix
            specific_force = np.einsum("nij,nj->ni", quat_to_matrix(block.quat[i]), block.accel[i])
            nav = device_navigation(block.truth["position"], block.truth["velocity"], specific_force,
                                    *self.navigation)
        # the unit's own estimate (companion INS) replaces the truth's position and velocity
        samples = reexpress(Samples(time_ns, block.accel[i], block.gyro[i], quat=quat, temperature_c=temperature,
                                    **{**nav, **companion}, **increments, start_ns=self.start_ns), body, "FRD")
        if self.device is not None:     # a device may be asked for any field its format knows at any moment
            samples.euler = quat_to_euler(samples.quat)
        else:      # the angles of the attitude sent: VectorNav YawPitchRoll and MIP Euler read euler, else zeros
            samples.euler = attitude.to_euler(samples.quat)
        return samples

    def _attitude_change(self, block, quat: np.ndarray) -> np.ndarray:
        """Each interval's attitude change from the true attitudes at its ends (attitude.attitude_change), in the
        scene's body axes (reexpress turns it with the rest); the last sample of the previous block is kept for the
        next block's first interval. The stream's first sample, and the first after a loop restarts the scene, has
        no attitude before it: its change is the rotation by its increment."""
        dtheta = block.dtheta[self.imu_index]
        if self._before is not None and self._before[0] == block.k0:
            quat_first, dtheta_first = self._before[1], self._before[2]
        else:
            dtheta_first = dtheta[:1]
            quat_first = attitude.multiply(quat[:1], attitude.conjugate(attitude.from_rotation_vector(dtheta_first)))
        self._before = (block.k0 + len(block), quat[-1:].copy(), dtheta[-1:].copy())
        return attitude.attitude_change(quat, np.concatenate((quat_first, quat[:-1])), dtheta,
                                        np.concatenate((dtheta_first, dtheta[:-1])), not self.exact_gyro)

    def encode(self, block, time_ns: np.ndarray) -> tuple[list, int]:
        """Per-sample prepared payloads for one block, and the saturation count after it. A device stream
        gets the raw samples: its device encodes each one at its deadline, with the configuration then."""
        if self.device is not None:
            return self.samples(block, time_ns), 0
        encoded = self.encoder.encode(self.samples(block, time_ns))
        if self.info.kind == "serial":
            items = Packets(bytes(encoded.data), encoded.offsets.tolist())
        else:
            prepare = self.transport.prepare
            bounds = np.searchsorted(encoded["sample"], np.arange(len(time_ns) + 1)).tolist()
            items = [prepare(encoded[bounds[j]:bounds[j + 1]], time_ns[j]) for j in range(len(time_ns))]
        return items, _saturation_total(self.encoder)

    def send_reply(self, item) -> None:
        """A reply to the driver: sent now, or kept (in order, before any sample) when the link is full. A
        driver waits for its answer while samples keep coming: a sample may be dropped, a reply is not, unless
        _MAX_WAITING are already waiting (then it is counted in replies_dropped)."""
        if not self._waiting and self.transport.send(item):
            self.replies_sent += 1
        elif len(self._waiting) < _MAX_WAITING:
            self._waiting.append(item)
        else:
            self.replies_dropped += 1

    def send_waiting_replies(self) -> bool:
        """Send the replies the link refused before, in order; whether none is left waiting."""
        waiting = self._waiting
        while waiting:
            if not self.transport.send(waiting[0]):
                return False
            waiting.popleft()
            self.replies_sent += 1
            self.replies_delayed += 1
        return True

    def send_sample(self, payload) -> None:
        """One sample's payload (None: nothing due), after any reply still waiting: while one waits the sample
        is dropped (counted), so a reply never falls behind the samples."""
        if not self.send_waiting_replies():
            if payload is None:
                self.idle += 1
            else:
                self.dropped += 1
        elif payload is None:
            self.idle += 1
        elif self.transport.send(payload):
            self.sent += 1
        else:
            self.dropped += 1

    def send_samples(self, payloads: list) -> None:
        """Several samples' payloads at once, in order (the send loop catching up after missed deadlines): replies
        still waiting go first, as for one sample, then the payloads in one `Transport.send_many`."""
        due = [p for p in payloads if p is not None]
        self.idle += len(payloads) - len(due)
        if not due:
            return
        sent = self.transport.send_many(due) if self.send_waiting_replies() else 0
        self.sent += sent
        self.dropped += len(due) - sent

    def sample_queue(self) -> None:
        queued = self.transport.queued()
        if queued is not None:
            self.queue_max = max(queued, self.queue_max or 0)

    def close(self) -> None:
        if self.transport is not None:
            self.send_waiting_replies()
            self.replies_dropped += len(self._waiting)
            self._waiting.clear()
            self.transport.finish()
            self.sample_queue()
            self.link = self.transport.link_report()
            if self.queue_max is not None:
                self.link["queue_max_bytes"] = self.queue_max
            self.transport.close()
            self.transport = None

    def device_item(self, samples, i: int):
        """What the device sends for sample i now, prepared for the transport; None when nothing is due."""
        return self._prepared(self.device.output(samples, i), samples, i)

    def device_items(self, samples, i: int, k: int) -> list:
        """device_item for samples i to k - 1, asked of the device at once (Device.output_many)."""
        return [self._prepared(out, samples, m) for m, out in enumerate(self.device.output_many(samples, i, k), i)]

    def _prepared(self, out, samples, i: int):
        if not len(out):
            return None
        if self.info.kind == "serial":
            return out
        return self.transport.prepare(out, int(samples.time_ns[i]))

    def summary(self) -> dict:
        out = {"imu": self.config.imu, "format": self.config.format, "target": self.config.target,
               "sent": self.sent, "dropped": self.dropped, "saturated": self.saturated}
        if self.device is not None:
            out["device"] = {**self.device.stats.as_dict(), "replies_sent": self.replies_sent,
                             "replies_delayed": self.replies_delayed, "replies_dropped": self.replies_dropped,
                               "idle": self.idle}
        if self.ignored_input:
            out["ignored_input"] = self.ignored_input
        out["link"] = self.link
        return out


# Replies kept while the link is full: a driver sends a command and waits, so a handful is what it can have
# outstanding; more means the link has stopped taking anything and the rest are counted as dropped.
_MAX_WAITING = 64


def _companion_fields(block, i: int, quat, temperature):
    """The companion sensors' Samples fields of IMU i (imu_emulator.companions), and the attitude and temperature
    as the part reports them: its own estimate's attitude (the INS error turned in on the NED side) and the
    barometer's temperature where no temperature effect gives the IMU's. The magnetometer's vector is in the
    sensor's axes, as accel and gyro are."""
    if block.companion is None or not block.companion[i]:
        return quat, temperature, {}
    fields = dict(block.companion[i])
    error = fields.pop("ins_attitude_error_rad", None)
    for name in ("ins_quat", "ins_euler"):     # the files' copy of the estimate's attitude: turned in below
        fields.pop(name, None)
    if error is not None:
        from imu_emulator.companions.ins import estimate_quat
        quat = estimate_quat(quat, error)
    baro_temperature = fields.pop("baro_temperature_c", None)
    return quat, temperature if temperature is not None else baro_temperature, fields


def _saturation_total(encoder) -> int:
    return encoder.saturated.total


def build_streams(configs: list[StreamConfig], imu_names, rate_hz: float) -> list[Stream]:
    streams = []
    for config in configs:
        if config.imu not in imu_names:
            raise StreamError(f"--imu: no IMU named {config.imu!r} (scene has: {', '.join(imu_names)})")
        try:
            info = firmware_protocols.get(config.format)
        except KeyError as exc:
            raise StreamError(exc.args[0]) from None
        streams.append(Stream(config, list(imu_names).index(config.imu), info, rate_hz))
    return streams
