"""Building damaged byte streams for the serial decoders' fuzz tests."""
import numpy as np


def damaged_stream(batch, parts, seed: int) -> bytes:
    """Concatenate `parts`: bytes go in as they are (garbage, look-alike headers); an int i puts packet i
    of `batch` in, with a bit flipped 30 % of the time and cut short 20 % of the time."""
    rng = np.random.default_rng(seed)
    stream = bytearray()
    for part in parts:
        if isinstance(part, int):
            packet = bytearray(batch.packet(part))
            if rng.random() < 0.3:
                packet[rng.integers(len(packet))] ^= 1 << int(rng.integers(8))
            if rng.random() < 0.2:
                packet = packet[:rng.integers(len(packet))]
            stream += packet
        else:
            stream += part
    return bytes(stream)


def feed_in_chunks(decoder, stream: bytes, size: int) -> list:
    return [p for k in range(0, len(stream), size) for p in decoder.feed(stream[k:k + size])]
