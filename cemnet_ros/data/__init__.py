"""Small data that ships with the package (procedural shapes for demos, tests and benchmarks)."""
