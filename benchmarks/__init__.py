"""The odometry robustness benchmark (``scripts/bench_robustness.py``): ``ScanAligner`` against KISS-ICP and
small_gicp on the same scans. :mod:`.robustness` runs it; the other modules are its parts (methods, scan sets,
metrics, tables). :mod:`.libraries` compares the classical pieces with small_gicp and KISS-ICP
(``scripts/bench_libraries.py``); :mod:`.dds_probe` is the harness of the node benchmarks over DDS
(``scripts/bench_dds.py``, ``scripts/soak_node.py``)."""
