"""Output files: one writer per file format, atomic creation, size estimates."""
