"""The real-data benchmark's readers and metrics (benchmarks.real) on small made-up sequences."""
import numpy as np
from street_scene import make_transform

from benchmarks.real import Sequence, StepResult, balm_sequence, real_table, sequence_metrics

PERIOD_NS = 500_000_000


def straight_sequence(n=6):
    poses = [make_transform(t=(0.5 * k, 0.0, 0.0)) for k in range(n)]
    scans = [np.random.default_rng(k).uniform(-5, 5, (200, 3)) for k in range(n)]
    return Sequence("straight", scans, poses, [k * PERIOD_NS for k in range(n)], max_range=50.0)


def test_off_steps_are_counted_apart_as_accepted_and_flagged():
    seq = straight_sequence()
    published = [p.copy() for p in seq.poses]
    for k in range(3, len(published)):  # step 3 is 2 m off; the steps after it are right again
        published[k] = published[k] @ make_transform(t=(2.0, 0.0, 0.0))
    results = [StepResult(p, True, False, 10.0, "") for p in published]
    results[5] = StepResult(published[5] @ make_transform(yaw=np.radians(5.0)), False, True, 30.0, "flagged")
    metrics = sequence_metrics(seq, results)
    assert [s["index"] for s in metrics["off_steps"]] == [3, 5]
    assert metrics["off_accepted"] == 1 and metrics["off_flagged"] == 1
    assert metrics["worst_step_m"] > 1.9 and metrics["recovered_share"] == 0.2
    assert metrics["period_ms"] == 500.0 and metrics["ms_p50"] == 10.0
    assert "| straight | cemnet |" in real_table({"straight": {"cemnet": metrics}})


def test_a_failed_scan_is_an_infinitely_wrong_step_and_no_ate():
    seq = straight_sequence(3)
    results = [StepResult(seq.poses[0], True, False, 1.0, ""), StepResult(None, False, False, 1.0, "boom"),
               StepResult(seq.poses[2], True, False, 1.0, "")]
    metrics = sequence_metrics(seq, results)
    assert metrics["ate_m"] is None and metrics["off_flagged"] == 2


def test_keyframes_take_every_kth_scan_thinned_and_first_cuts():
    seq = straight_sequence(7)
    sparse = seq.keyframes(3, 50)
    assert len(sparse.scans) == 3 and all(len(s) == 50 for s in sparse.scans)
    assert sparse.stamps_ns == [0, 3 * PERIOD_NS, 6 * PERIOD_NS] and sparse.period_s == 1.5
    np.testing.assert_array_equal(sparse.poses[1], seq.poses[3])
    assert all(np.isin(s, full).all() for s, full in zip(sparse.scans, seq.scans[::3]))  # points of the scan
    assert len(seq.first(2).scans) == 2 and seq.length_m == 3.0


def test_balm_folder_is_read_with_its_stamps_and_poses(tmp_path):
    poses = [make_transform(t=(0.3 * k, 0.0, 0.0)) for k in range(2)]
    rows = []
    for k, pose in enumerate(poses):
        stamped = pose.copy()
        stamped[3, 3] = 100.0 + 0.5 * k  # BALM keeps the stamp (s) in the bottom-right entry
        rows.extend(",".join(f"{v:.9f}" for v in row) for row in stamped)
        points = np.random.default_rng(k).uniform(-1, 1, (20, 3)).astype(np.float32)
        header = ("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 20\nHEIGHT 1\n"
                  "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 20\nDATA binary\n")
        (tmp_path / f"full{k}.pcd").write_bytes(header.encode() + points.tobytes())
    (tmp_path / "alidarPose.csv").write_text("\n".join(rows) + "\n")
    seq = balm_sequence(tmp_path)
    assert seq.stamps_ns == [100_000_000_000, 100_500_000_000]
    np.testing.assert_allclose(seq.poses[1], poses[1], atol=1e-9)
    assert seq.scans[0].shape == (20, 3) and seq.scans[0].dtype == np.float64
