"""The robustness benchmark (benchmarks, scripts/bench_robustness.py): its metrics on hand-made poses, and a
tiny end-to-end run of `large_motion`."""
from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from benchmarks.drives import make_drive
from benchmarks.fast_gaps import GAPS, LEAD_TICKS, fast_drive
from benchmarks.metrics import accepted_wrong, ate_first_pose, end_drift_percent, relative_error, summarize
from benchmarks.pairs import Pair, pair_record
from benchmarks.robustness import QUICK, RobustnessConfig, run
from benchmarks.sequences import event_outcome
from benchmarks.speed import ping_pong
from benchmarks.streams import Scan, run_stream, step_records
from benchmarks.tables import fast_gaps_table
from cemnet_ros.data.scenes import COURTYARD_BOUNDS, courtyard_scene, in_free_space


def _pose(x=0.0, y=0.0, z=0.0, yaw_deg=0.0):
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix()
    out[:3, 3] = x, y, z
    return out


def _step(rte, rre, accepted=True, error=None, index=1):
    return {"case": "c", "index": index, "accepted": accepted, "reason": "", "rte_m": rte, "rre_deg": rre,
            "ms": 10.0, "error": error}


def test_relative_error():
    truth = _pose(1.0, 0.0, 0.0, 10.0)
    assert relative_error(truth, truth) == pytest.approx((0.0, 0.0), abs=1e-6)
    rte, rre = relative_error(truth @ _pose(0.0, 0.3, 0.0, 2.0), truth)
    assert rte == pytest.approx(0.3) and rre == pytest.approx(2.0)


def test_summarize_counts_recall_precise_and_accepted_wrong():
    steps = [
        _step(0.05, 0.2),  # precise
        _step(0.5, 1.0),  # recall, accepted while wrong
        _step(0.05, 0.7, accepted=False),  # recall, flagged (not "accepted wrong")
        _step(3.0, 1.0),  # no recall, accepted while wrong
        _step(None, None, accepted=False, error="ValueError: boom"),  # failed
    ]
    s = summarize(steps)
    assert (s["steps"], s["failed"], s["flagged"], s["accepted_wrong"]) == (5, 1, 1, 2)
    assert s["recall"] == pytest.approx(3 / 5) and s["precise"] == pytest.approx(1 / 5)
    assert [w["rte_m"] for w in s["accepted_wrong_steps"]] == [0.5, 3.0]
    assert s["rte_median_accepted_m"] == pytest.approx(0.5) and s["errors"] == ["ValueError: boom"]
    assert accepted_wrong(_step(0.10, 0.5)) is False  # thresholds are strict
    assert accepted_wrong(_step(0.11, 0.0)) and accepted_wrong(_step(0.0, 0.51))
    assert accepted_wrong(_step(float("nan"), float("nan")))  # a NaN pose accepted is wrong


def test_ate_aligns_only_the_first_pose():
    truth = [_pose(float(i), 0.0) for i in range(5)]
    offset = _pose(10.0, -3.0, 1.0, 70.0)  # another odom origin: removed by the first-pose alignment
    assert ate_first_pose([offset @ p for p in truth], truth) == pytest.approx(0.0, abs=1e-9)
    shifted = [offset @ p @ _pose(0.0, 0.2 if i else 0.0) for i, p in enumerate(truth)]  # 0.2 m off after pose 0
    assert ate_first_pose(shifted, truth) == pytest.approx(np.sqrt(4 * 0.04 / 5))
    yawed = [truth[0]] + [_pose(0, 0, 0, 90.0) @ p for p in truth[1:]]  # a rotation is not aligned away
    assert ate_first_pose(yawed, truth) > 1.0


def test_end_drift_percent():
    truth = [_pose(float(i), 0.0) for i in range(11)]  # 10 m
    est = [_pose(1.1 * i, 0.0) for i in range(11)]  # 1 m too far at the end
    assert end_drift_percent(est, truth, 10.0) == pytest.approx(10.0)
    assert end_drift_percent(est, truth, 0.0) is None


def _scan(tick, pose, accepted=True, error=None):
    return Scan(tick, pose, accepted, "", 1.0, error)


def test_step_records_failures_and_gaps():
    truth = {t: _pose(float(t)) for t in range(5)}
    results = [_scan(0, truth[0]), _scan(1, None, False, "ScanRejected: few"), _scan(3, _pose(3.05)),
               _scan(4, _pose(4.05), accepted=False)]
    records = step_records("s", results, truth)
    assert [r["index"] for r in records] == [1, 3, 4]
    assert records[0]["error"] == "ScanRejected: few" and records[0]["rte_m"] is None
    assert records[1]["rte_m"] == pytest.approx(0.05)  # 0 -> 3: the failed scan is skipped
    assert records[2]["rte_m"] == pytest.approx(0.0, abs=1e-9) and records[2]["accepted"] is False
    first_failed = step_records("s", [_scan(0, None, False, "E: x"), _scan(1, truth[1])], truth)
    assert first_failed[0]["error"] == "no earlier scan was processed"


def test_event_outcome_recovered_resumed_flagged():
    truth = [_pose(float(t)) for t in range(4)] + [_pose(10.0 + t, 5.0, 0.0, 60.0) for t in range(4, 8)]
    event = {"kind": "kidnap", "tick": 4}
    # Flags the teleport, keeps tracking from the new place: resumed, not recovered (that needs re-localisation).
    pred = truth[3] @ _pose(1.0)
    tracked = ([_scan(t, truth[t]) for t in range(4)] + [_scan(4, pred, accepted=False)]
               + [_scan(t, pred @ np.linalg.inv(truth[4]) @ truth[t]) for t in range(5, 8)])
    assert event_outcome(event, tracked, truth) == {"kind": "kidnap", "tick": 4, "recovered": False,
                                                    "resumed": True, "flagged": True}
    # Re-localised across the jump: recovered.
    exact = [_scan(t, truth[t]) for t in range(8)]
    assert event_outcome(event, exact, truth)["recovered"] is True
    # Lost: the steps after the event are wrong.
    lost = [_scan(t, truth[t]) for t in range(4)] + [_scan(t, _pose(3.0 + 0.5 * t)) for t in range(4, 8)]
    out = event_outcome(event, lost, truth)
    assert not out["recovered"] and not out["resumed"] and not out["flagged"]
    assert event_outcome({"kind": "dropout", "tick": 9}, exact, truth)["recovered"] is None  # too late


def test_ping_pong_and_failing_method_counted():
    assert ping_pong(3, 7) == [0, 1, 2, 1, 0, 1, 2]

    class Broken:
        def __init__(self, max_range):
            pass

        def process(self, points, stamp_ns):
            raise RuntimeError("kernel crashed")

    pts = np.zeros((10, 3))
    results = run_stream(Broken, 100.0, [pts, pts], [0, 1])
    pair = Pair("p", pts, pts, np.eye(4))
    record = pair_record(pair, results)
    assert record["error"] == "first scan: RuntimeError: kernel crashed" and record["accepted"] is False


def test_drive_has_its_events_and_stays_in_free_space():
    drive = make_drive(60, np.random.default_rng(3))
    kinds = sorted(e["kind"] for e in drive.events)
    assert kinds == sorted(["dropout", "dropout", "stop", "go", "yaw_swing", "yaw_reverse", "kidnap"])
    jump = np.linalg.norm(drive.poses[drive.kidnap_tick][:2, 3] - drive.poses[drive.kidnap_tick - 1][:2, 3])
    assert jump > 4.0
    assert len(drive.delivered) < 60 and 0 in drive.delivered
    assert in_free_space(courtyard_scene(), np.array([p[:3, 3] for p in drive.poses]), COURTYARD_BOUNDS)


def test_fast_drive_skips_its_gap_keeps_to_the_lane_and_brakes_only_in_the_gap():
    for seed in range(6):
        poses, delivered, draw = fast_drive(np.random.default_rng(seed))
        skipped = sorted(set(range(len(poses))) - set(delivered))
        assert skipped == list(range(LEAD_TICKS, LEAD_TICKS + len(skipped)))
        assert GAPS[0] - 1e-9 <= len(skipped) * 0.1 <= GAPS[1] + 1e-9
        x = np.array([p[0, 3] for p in poses])
        speeds = np.diff(x) / 0.1
        assert speeds[0] == pytest.approx(draw["speed_mps"])
        assert np.all(np.diff(speeds[: LEAD_TICKS + 1]) == pytest.approx(0.0))  # steady before the gap
        after = speeds[LEAD_TICKS + len(skipped):]
        assert np.all(np.diff(after) == pytest.approx(0.0))  # and after it, at the speed it braked to
        assert after[0] == pytest.approx(max(draw["speed_mps"] - draw["brake_mps2"] * len(skipped) * 0.1, 1.0))
        assert in_free_space(courtyard_scene(), np.array([p[:3, 3] for p in poses]), COURTYARD_BOUNDS, margin=0.5)


def test_fast_gaps_table_counts_the_drives_that_held():
    data = {"m": {"drives": [{"ate_m": 0.01, "flagged": 0}, {"ate_m": 2.0, "flagged": 3}, {"ate_m": None,
                                                                                          "flagged": 5}]}}
    assert fast_gaps_table(data).splitlines()[-1] == "| m | 3 | 1.005 | 2.000 | 1 | 8 |"


def test_large_motion_end_to_end():
    """2 pairs through every importable method; keys of the JSON (the pipeline's accuracy is not checked)."""
    config = RobustnessConfig(sets=("large_motion",), **{**QUICK, "pairs": 2})
    seen: list[list[str]] = []
    report = run(config, after_set=lambda partial: seen.append(list(partial.results)))
    data = json.loads(report.to_json())
    assert data["meta"]["seeds"]["large_motion"] == 0 and data["meta"]["sizes"]["pairs"] == 2
    methods = data["sets"]["large_motion"]
    peers = (("kiss-icp", "kiss_icp"), ("genz-icp", "genz_icp"), ("gicp", "small_gicp"))
    expected = ["cemnet"] + [name for name, module in peers if importlib.util.find_spec(module) is not None]
    assert sorted(methods) == sorted(expected)
    for res in methods.values():
        assert len(res["steps"]) == 2
        assert {"steps", "failed", "flagged", "recall", "precise", "accepted_wrong", "accepted_wrong_steps",
                "ms_median", "ms_p90"} <= set(res["summary"])
        assert res["summary"]["steps"] == 2
    assert seen == [["large_motion"]]  # the results so far, after each set
    assert "| large_motion | cemnet | 2 |" in report.to_markdown()


def test_config_checks_sizes_and_skips_kitti_without_data(tmp_path):
    with pytest.raises(ValueError, match="--pairs must be >= 1"):
        RobustnessConfig(pairs=0)
    with pytest.raises(ValueError, match="--seq-scans must be >= "):
        RobustnessConfig(seq_scans=10)
    with pytest.raises(ValueError, match="unknown"):
        RobustnessConfig(sets=("magic",))
    report = run(RobustnessConfig(sets=("kitti_gaps", "speed"), methods=(), kitti=tmp_path / "none"))
    assert report.results == {} and [line.split(":")[0] for line in report.skipped] == ["kitti_gaps", "speed"]
    assert report.to_markdown().startswith("skip kitti_gaps: the KITTI sample")


def test_script_turns_its_flags_into_the_config():
    """The script's wiring, without a run: a size below 1 is refused with the flag's name (exit 2)."""
    script = Path(__file__).resolve().parents[2] / "scripts" / "bench_robustness.py"
    done = subprocess.run([sys.executable, str(script), "--quick", "--pairs", "0"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 2 and "error: --pairs must be >= 1" in done.stderr


def test_the_pipeline_under_test_takes_parameter_overrides():
    from benchmarks.odometry import available_methods

    default = available_methods(["cemnet"])["cemnet"](100.0)
    lean = available_methods(["cemnet"], {"recovery.search.n_scatter": 125})["cemnet"](100.0)
    assert default._aligner.config.recovery.search.n_scatter == 2000
    assert lean._aligner.config.recovery.search.n_scatter == 125
    script = Path(__file__).resolve().parents[2] / "scripts" / "bench_robustness.py"
    bad = subprocess.run([sys.executable, str(script), "--set", "recovery.search.bogus=1"], capture_output=True,
                         text=True, timeout=120)
    assert bad.returncode == 2 and "recovery.search.bogus" in bad.stderr
