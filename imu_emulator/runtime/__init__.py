"""Compile, cache and load kernels; Simulation fills sample blocks; the blocks themselves."""
