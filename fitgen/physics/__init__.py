"""The sensor and what it reads: sensor files, the magnet's field, poses, transfers, built units, datasets, simulation, observability, scenes."""
