"""Output files: the column schema (columns), what a format is (base), one module per format (formats/, found
by suffix), atomic creation (atomic), CSV's fast number text (csv_text)."""
