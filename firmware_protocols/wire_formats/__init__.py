"""The wire formats, one module per format family: each registers its formats (firmware_protocols.registry)
when imported. The list is found, not kept: the registry imports every module of this package whose name does
not start with "_"; helpers shared by several formats live beside this package (crc, packing, can_signals, ...)."""
