"""Smoke runs of cemnet-eval, cemnet-bench and cemnet-register on tiny synthetic data (small CEM settings)."""
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cemnet_ros.data.shapes import bracket_shape
from cemnet_ros.io.pointcloud_files import write_ply

core = pytest.importorskip("cemnet_ros.core.registration", reason="the CEMNet core is absent")
from cemnet_ros.align_clouds import engine_scale  # noqa: E402
from cemnet_ros.core.checkpoint import DEFAULT_WEIGHTS, save_weights  # noqa: E402
from cemnet_ros.core.network import SamplingNetwork  # noqa: E402
from cemnet_ros.tools import bench_cli, eval_cli, register_cli  # noqa: E402
from cemnet_ros.tools.register_cli import parsed_scale  # noqa: E402

SMALL_CEM = ["--cem.n_candidates", "100", "--cem.n_iters", "3"]


@pytest.fixture(scope="module")
def shapes_npz(tmp_path_factory):
    path = tmp_path_factory.mktemp("data") / "shapes.npz"
    points = np.stack([bracket_shape(1024, seed=i) for i in range(4)])
    np.savez(path, points=points, labels=np.array([1, 2, 21, 22]), split=np.array(["train", "test", "test", "test"]))
    return path


@pytest.fixture(scope="module")
def random_weights(tmp_path_factory):
    import torch

    torch.manual_seed(0)
    return save_weights(tmp_path_factory.mktemp("w") / "random.npz", SamplingNetwork().state_dict(), {"test": True})


def test_eval_writes_json_and_markdown(shapes_npz, random_weights, tmp_path, capsys):
    out_json, out_md = tmp_path / "out" / "r.json", tmp_path / "r.md"
    code = eval_cli.main(["--data", str(shapes_npz), "--weights", str(random_weights), "--methods", "cemnet,icp",
                          "--limit", "2", "--batch-size", "2", "--out-json", str(out_json), "--out-md", str(out_md),
                          *SMALL_CEM])
    assert code == 0
    printed = capsys.readouterr().out
    assert "| cemnet |" in printed and "| icp |" in printed and "recall" in printed
    report = json.loads(out_json.read_text())
    assert set(report["aggregates"]) == {"cemnet", "icp"}
    assert len(report["per_pair"]["cemnet"]) == len(report["per_pair"]["icp"]) == 2
    assert report["config"]["registration"]["cem"]["n_candidates"] == 100
    assert report["config"]["protocol"]["n_partial"] == 768
    first = report["per_pair"]["cemnet"][0]
    assert 0.0 <= first["fitness"] <= 1.0 and np.asarray(first["rotation"]).shape == (3, 3)
    assert out_md.read_text() in printed


def test_eval_network_mode_unseen_identity(shapes_npz, random_weights, tmp_path, capsys):
    out_json = tmp_path / "n.json"
    code = eval_cli.main(["--data", str(shapes_npz), "--weights", str(random_weights), "--methods", "cemnet",
                          "--mode", "network", "--setting", "unseen", "--out-json", str(out_json)])
    assert code == 0
    report = json.loads(out_json.read_text())
    assert [p["label"] for p in report["per_pair"]["cemnet"]] == [21, 22]
    assert "cemnet (network only)" in capsys.readouterr().out
    # identity prior, no network: the N(0, I) ablation
    assert eval_cli.main(["--data", str(shapes_npz), "--prior", "identity", "--methods", "cemnet", "--limit", "1",
                          "--full", *SMALL_CEM]) == 0


@pytest.mark.parametrize("extra, message", [
    (["--methods", "cemnet,magic"], "unknown"),
    (["--weights", "/nonexistent/w.npz"], "not found"),
    (["--cem.n_candidates", "1"], "n_candidates"),
    (["--limit", "0"], ">= 1"),
])
def test_eval_bad_arguments_exit_nonzero(shapes_npz, extra, message, capsys):
    assert eval_cli.main(["--data", str(shapes_npz), "--methods", "cemnet", *extra]) == 2
    assert message in capsys.readouterr().err


def test_eval_missing_and_corrupt_data(tmp_path, capsys):
    assert eval_cli.main(["--data", str(tmp_path / "none.npz"), "--methods", "icp"]) == 2
    assert "not found" in capsys.readouterr().err
    (tmp_path / "bad.npz").write_bytes(b"not an archive")
    assert eval_cli.main(["--data", str(tmp_path / "bad.npz"), "--methods", "icp"]) == 2
    assert "cannot read" in capsys.readouterr().err


def test_eval_pickle_needs_opt_in(shapes_npz, tmp_path, capsys):
    (tmp_path / "w.pth").write_bytes(b"\x80\x02}q\x00.")
    assert eval_cli.main(["--data", str(shapes_npz), "--weights", str(tmp_path / "w.pth")]) == 2
    assert "allow-pickle" in capsys.readouterr().err


def test_bench_synthetic(tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert bench_cli.main(["--pairs", "2", "--warmup", "1", "--prior", "identity", "--json", str(out),
                           *SMALL_CEM]) == 0
    printed = capsys.readouterr().out
    assert "median" in printed and "ratio" in printed and "numba" in printed
    report = json.loads(out.read_text())
    assert len(report["per_pair_ms"]["cemnet"]) == 2 and report["ratio_median"] > 0


def _parse_matrix(text: str) -> np.ndarray:
    rows = [line for line in text.splitlines() if line and not line.startswith("#")][:4]
    return np.array([[float(v) for v in row.split()] for row in rows])


@pytest.mark.skipif(not DEFAULT_WEIGHTS.exists(), reason="the package's default weights are absent")
def test_register_two_files_recovers_transform(tmp_path, capsys):
    shape = bracket_shape(1024, seed=2).astype(np.float64)
    r = Rotation.from_euler("zyx", [20, 10, 15], degrees=True).as_matrix()
    t = np.array([0.2, -0.1, 0.15])
    write_ply(tmp_path / "src.ply", shape[:768])
    np.save(tmp_path / "tgt.npy", shape[256:] @ r.T + t)
    assert register_cli.main([str(tmp_path / "src.ply"), str(tmp_path / "tgt.npy"), "--cem.n_candidates", "300"]) == 0
    out = capsys.readouterr().out
    transform = _parse_matrix(out)
    assert transform.shape == (4, 4) and "fitness" in out and "sigma" in out
    assert "method: engine" in out  # an object-scale cloud: the paper's engine, as before
    np.testing.assert_allclose(transform[3], [0, 0, 0, 1])
    angle = np.degrees(np.arccos(np.clip((np.trace(r.T @ transform[:3, :3]) - 1) / 2, -1, 1)))
    assert angle < 2.0 and np.linalg.norm(transform[:3, 3] - t) < 0.03


def test_register_scale_handling(tmp_path, capsys):
    small = bracket_shape(256, seed=1).astype(np.float64)
    assert engine_scale(small, small) == 1.0
    big = small * 40.0
    assert 20.0 < engine_scale(big, big) <= 40.0
    assert parsed_scale("2.5") == 2.5 and parsed_scale("auto") is None
    with pytest.raises(ValueError, match="positive"):
        parsed_scale("-1")
    # scaled clouds, the engine forced: identity prior + tiny CEM; the printed translation is in the clouds' units
    write_ply(tmp_path / "a.ply", big)
    write_ply(tmp_path / "b.ply", big + np.array([4.0, 0.0, 0.0]))
    assert register_cli.main([str(tmp_path / "a.ply"), str(tmp_path / "b.ply"), "--mode", "engine", "--prior",
                              "identity", "--scale", "40", "--json", str(tmp_path / "out" / "r.json"), *SMALL_CEM]) == 0
    printed = capsys.readouterr().out
    assert "scale 40" in printed and "method: engine" in printed
    result = json.loads((tmp_path / "out" / "r.json").read_text())  # the printed figures, in JSON
    assert result["scale"] == 40.0 and np.asarray(result["T_target_source"]).shape == (4, 4)
    np.testing.assert_allclose(_parse_matrix(printed), result["T_target_source"], atol=1e-6)


def test_register_errors(tmp_path, capsys):
    assert register_cli.main([str(tmp_path / "a.ply"), str(tmp_path / "b.ply")]) == 2
    assert "not found" in capsys.readouterr().err
    (tmp_path / "bad.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\n")
    (tmp_path / "ok.npy").write_bytes(b"")
    np.save(tmp_path / "ok.npy", bracket_shape(64))
    assert register_cli.main([str(tmp_path / "bad.ply"), str(tmp_path / "ok.npy")]) == 2
    assert "not terminated" in capsys.readouterr().err
    np.save(tmp_path / "two.npy", np.zeros((2, 3)))
    assert register_cli.main([str(tmp_path / "two.npy"), str(tmp_path / "ok.npy"), "--prior", "identity"]) == 2
    assert "points" in capsys.readouterr().err
    assert register_cli.main([str(tmp_path / "ok.npy"), str(tmp_path / "ok.npy"), "--scale", "abc"]) == 2
    assert "--scale" in capsys.readouterr().err


def test_ablation_table_script(shapes_npz, random_weights, tmp_path, capsys):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "scripts" / "ablation_table.py"
    spec = importlib.util.spec_from_file_location("ablation_table", path)
    ablation = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ablation)
    assert ablation.main(["--data", str(shapes_npz), "--weights", str(random_weights), "--settings", "clean,unseen",
                          "--limit", "1", "--out", str(tmp_path)]) == 0
    results = json.loads((tmp_path / "ablation.json").read_text())
    assert set(results) == {"clean", "unseen"}
    rows = results["clean"]
    assert list(rows) == ["CEMNet, project weights", "no sampling network, prior N(0, I)",
                          "sampling network alone (mu0), project weights",
                          "CEM without future reward (M = 0), project weights"]
    assert all(r["n_pairs"] == 1 and 0.0 <= r["recall"] <= 1.0 for r in rows.values())
    assert (tmp_path / "ablation.md").read_text().count("\n| clean |") == 4
    assert ablation.main(["--data", str(shapes_npz), "--official-dir", str(tmp_path / "none"), "--settings", "clean",
                          "--out", str(tmp_path)]) == 2
