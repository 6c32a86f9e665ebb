"""The odometry robustness benchmark (``scripts/bench_robustness.py``): ``ScanAligner`` against KISS-ICP and
small_gicp on the same scans. :mod:`.robustness` runs it; the other modules are its parts (methods, scan sets,
metrics, tables)."""
