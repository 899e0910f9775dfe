"""A run's files and process: its directory layout, atomic writes, cores and signals."""
