"""Kernel source for exactly the effects a scene names: template, plan, generator, increments."""
