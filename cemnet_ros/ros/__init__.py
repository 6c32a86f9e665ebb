"""ROS 2 (rclpy) front end of cemnet_ros: the ``align_node`` executable.

Importing it sets the thread policy of a node process, before numpy, torch and numba start their thread
pools (a value already in the environment wins):

- ``OPENBLAS_NUM_THREADS=1``: numpy's BLAS calls here are small (3x3 rotations of a scan); a second BLAS
  thread only spins after each one, on the cores the numba kernels need;
- ``OMP_WAIT_POLICY=PASSIVE``: OpenMP threads (numba's, torch's) sleep between parallel regions instead of
  spinning. A robot computer is shared: spinning threads of idle pools halved the node's throughput under
  load (docs/node.md, "Threading");
- ``GOMP_SPINCOUNT=30000`` (libgomp, under numba's OpenMP layer): they sleep only after a short spin (tens of
  microseconds), so that the kernels one scan launches back to back find their threads awake: sleeping at once
  cost ~2 ms of a 15 ms scan, the short spin nothing measurable under overload.
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
os.environ.setdefault("GOMP_SPINCOUNT", "30000")
