"""Numerics any layer may use: derivatives and smoothing of sampled series, exact phase reduction, counter-based
random numbers."""
