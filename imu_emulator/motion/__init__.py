"""Motion of the reference point: the scene's trajectory and attitude as kernel lines (symbolic, sampled, tangent),
the Earth's geometry, and truth series."""
