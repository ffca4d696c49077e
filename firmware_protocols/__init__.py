"""Wire formats of real IMUs: plain arrays (SI units, sensor frame) in, bytes or CAN frames out."""
from firmware_protocols.base import (CAN_FRAME_DTYPE, CLASSIC_FRAME_DTYPE, FD_FRAME_DTYPE, DecoderStats, EncodeError,
                                     Packet, SaturationStats, Samples, SerialBatch)
from firmware_protocols.registry import FormatInfo, create_decoder, create_device, create_encoder, formats, get

__all__ = ["CAN_FRAME_DTYPE", "CLASSIC_FRAME_DTYPE", "FD_FRAME_DTYPE", "DecoderStats", "EncodeError", "FormatInfo",
           "Packet", "SaturationStats", "Samples", "SerialBatch", "create_decoder", "create_device", "create_encoder", "formats",
           "get"]
