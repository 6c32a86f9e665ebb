"""align_clouds and cemnet-register pick the method by size: metric scans go through the scan pipeline's pair
mode (precise on real LiDAR scans), object-scale clouds through the paper's engine."""
from __future__ import annotations

import json

import numpy as np
import pytest
from shared_data import KITTI, MODELNET, requires_shared

from cemnet_ros.align_clouds import METRIC_EXTENT, chosen_method

UNIT_CUBE = np.random.default_rng(0).uniform(-0.5, 0.5, (500, 3))


def test_auto_picks_the_engine_for_objects_and_the_scan_pipeline_for_metric_clouds():
    assert chosen_method(UNIT_CUBE, UNIT_CUBE) == "engine"
    street = UNIT_CUBE * (2.0 * METRIC_EXTENT)
    assert chosen_method(UNIT_CUBE, street) == "scan" and chosen_method(street, UNIT_CUBE) == "scan"
    assert chosen_method(street, street, "engine") == "engine" and chosen_method(UNIT_CUBE, UNIT_CUBE, "scan") == "scan"
    with pytest.raises(ValueError, match="mode must be one of"):
        chosen_method(UNIT_CUBE, UNIT_CUBE, "icp")


@requires_shared(MODELNET)
def test_auto_keeps_the_engine_for_every_modelnet_shape():
    points = np.load(MODELNET)["points"][..., :3]
    assert {chosen_method(shape, shape) for shape in points} == {"engine"}


@requires_shared(KITTI)
@pytest.mark.parametrize("target_index, source_index", [(0, 1), (3, 4)])
def test_register_two_kitti_scans_lands_within_2_cm_and_a_tenth_of_a_degree(tmp_path, capsys, target_index,
                                                                            source_index):
    from benchmarks.metrics import relative_error
    from cemnet_ros.data.kitti import kitti_scans
    from cemnet_ros.tools import register_cli

    scans = list(kitti_scans(KITTI))
    (_, T_world_target), (_, T_world_source) = scans[target_index], scans[source_index]
    velodyne = sorted((KITTI / "velodyne").glob("*.bin"))
    out = tmp_path / "r.json"
    assert register_cli.main([str(velodyne[source_index]), str(velodyne[target_index]), "--json", str(out)]) == 0
    assert "method: scan" in capsys.readouterr().out
    result = json.loads(out.read_text())
    assert result["method"] == "scan" and result["accepted"]
    rte_m, rre_deg = relative_error(np.asarray(result["T_target_source"]),
                                    np.linalg.inv(T_world_target) @ T_world_source)
    assert rte_m < 0.02 and rre_deg < 0.1, (rte_m, rre_deg)
