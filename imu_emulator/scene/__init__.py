"""Scene: a TOML file or a dict becomes a validated, frozen Scene (model, checks, sources, units, presets, flight
logs)."""
