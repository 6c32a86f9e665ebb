"""The bounded worker queue: drops the oldest, counts, survives errors."""
import threading
import time

from cemnet_ros.runtime.worker import BoundedWorker


def test_worker_drops_oldest_counts_and_survives_errors():
    gate, seen = threading.Event(), []

    def handler(item):
        if item == 0:
            gate.wait(5)
        if item == "bad":
            raise RuntimeError("boom")
        seen.append(item)

    errors = []
    worker = BoundedWorker(handler, maxsize=2, on_error=lambda item, exc: errors.append((item, str(exc))))
    try:
        assert worker.submit(0)
        deadline = time.monotonic() + 5
        while worker.stats().depth and time.monotonic() < deadline:  # item 0 is running and blocks
            time.sleep(0.01)
        results = [worker.submit(i) for i in (1, 2, 3, 4)]
        assert results == [True, True, False, False]
        stats = worker.stats()
        assert stats.depth == 2 and stats.drops == 2
        gate.set()
        assert worker.wait_idle(5)
        assert seen == [0, 3, 4]  # 1 and 2, the oldest, were dropped
        worker.submit("bad")
        worker.submit(5)
        assert worker.wait_idle(5)
        stats = worker.stats()
        assert seen[-1] == 5 and stats.errors == 1 and stats.processed == 4 and errors == [("bad", "boom")]
        assert stats.latency_max_s >= stats.latency_mean_s > 0
    finally:
        gate.set()
        assert worker.close()
    assert not worker.submit(6)
