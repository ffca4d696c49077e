"""numba-compiled code kept as machine code, so that a warm start needs no numba import.

Below both imu_emulator and firmware_protocols (it knows neither): `objects` writes a numba function's object code
behind a C entry and loads it with llvmlite alone; `lazy` declares numba functions that are built only when numba
is needed and otherwise called through their cached object code.
"""
