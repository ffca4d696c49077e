"""Pure geometry: WGS-84, navigation frames, geodesy, rotations."""
