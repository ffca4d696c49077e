"""Analyses of emulated and recorded data: alignment of two IMUs, replay fidelity, IMU records, Monte Carlo
batches, plots."""
