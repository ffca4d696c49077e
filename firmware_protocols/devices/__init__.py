"""Emulated devices: the state machines that answer a driver's commands (one module per format family).
See base.py for the interface; each module attaches its device to its formats in the registry."""
