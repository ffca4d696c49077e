"""CAN_FRAME_DTYPE rows -> python-can Messages, the one conversion every CAN target shares."""
from __future__ import annotations

import can
import numpy as np


def to_messages(rows: np.ndarray, timestamp: float = 0.0, bitrate_switch: bool = False) -> list[can.Message]:
    return [can.Message(timestamp=timestamp, arbitration_id=int(r["can_id"]), is_extended_id=bool(r["extended"]),
                        is_fd=bool(r["fd"]), bitrate_switch=bool(r["fd"]) and bitrate_switch,
                        data=r["data"][: r["length"]].tobytes(), is_rx=False, check=False)
            for r in rows]
