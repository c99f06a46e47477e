"""The thin command-line layer: argument parsing and printing; the work is done elsewhere."""
