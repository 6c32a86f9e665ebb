import numpy as np
import pytest
import torch
from shared_data import OFFICIAL_DIR, requires_shared

from cemnet_ros.core.checkpoint import (
    DEFAULT_WEIGHTS,
    NAMED_WEIGHTS,
    CheckpointError,
    load_network,
    load_weights,
    save_weights,
)
from cemnet_ros.core.network import SamplingNetwork


def test_safe_format_round_trip(tmp_path):
    net = SamplingNetwork()
    path = save_weights(tmp_path / "w.npz", net.state_dict(), {"epoch": 3})
    state, meta = load_weights(path)
    assert meta == {"epoch": 3}
    for key, value in net.state_dict().items():
        torch.testing.assert_close(state[key], value)


def test_safe_format_never_unpickles(tmp_path):
    # An object array would need pickle; the loader must refuse rather than run it.
    path = tmp_path / "evil.npz"
    np.savez(path, **{"param/x": np.array([object()], dtype=object)})
    with pytest.raises(CheckpointError):
        load_weights(path)


def test_pickles_need_explicit_opt_in(tmp_path):
    path = tmp_path / "model.pth"
    torch.save(SamplingNetwork().state_dict(), path)
    with pytest.raises(CheckpointError, match="allow_pickle"):
        load_weights(path)


@pytest.mark.parametrize("content", [b"", b"not a zip file at all", b"PK\x03\x04garbage"])
def test_corrupt_or_missing_files_raise_clear_errors(tmp_path, content):
    path = tmp_path / "broken.npz"
    path.write_bytes(content)
    with pytest.raises(CheckpointError):
        load_network(path)
    with pytest.raises(CheckpointError, match="not found"):
        load_network(tmp_path / "missing.npz")
    other = tmp_path / "weights.txt"
    other.write_text("x")
    with pytest.raises(CheckpointError, match="format"):
        load_network(other)


def test_mismatched_weights_are_rejected(tmp_path):
    path = save_weights(tmp_path / "small.npz", SamplingNetwork(emb_dims=64).state_dict())
    with pytest.raises(CheckpointError, match="do not fit"):
        load_network(path)


def test_bundled_default_weights_load():
    assert DEFAULT_WEIGHTS.is_file()
    assert isinstance(load_network(None), SamplingNetwork)


@requires_shared(OFFICIAL_DIR)
@pytest.mark.parametrize("name", sorted(p.name for p in OFFICIAL_DIR.glob("*.pth")) or ["none"])
def test_all_official_checkpoints_load_strictly(name):
    path = OFFICIAL_DIR / name
    state, meta = load_weights(path, allow_pickle=True)
    net = SamplingNetwork()
    net.load_state_dict(state, strict=True)
    assert meta["source"] == "official"


def test_convert_weights_cli_round_trip(tmp_path):
    from cemnet_ros.tools.convert_weights_cli import main
    pth = tmp_path / "official.pth"
    net = SamplingNetwork()
    # The official layout: keys under coarse_policy.emb_nn / coarse_policy.nn, plus the reflect buffer.
    state = {("coarse_policy.emb_nn." + k[len("embedding."):]) if k.startswith("embedding.")
             else ("coarse_policy.nn." + k[len("sigma_head."):]): v for k, v in net.state_dict().items()}
    state["coarse_policy.reflect"] = torch.eye(3)
    torch.save(state, pth)
    assert main([str(pth), str(tmp_path / "out.npz")]) == 0
    converted, _ = load_weights(tmp_path / "out.npz")
    for key, value in net.state_dict().items():
        torch.testing.assert_close(converted[key], value)
    assert main([str(tmp_path / "missing.pth"), str(tmp_path / "x.npz")]) == 2


def test_official_alias_loads_the_converted_official_weights():
    from cemnet_ros.core.checkpoint import OFFICIAL_WEIGHTS

    by_alias, by_path = load_network("official").state_dict(), load_network(OFFICIAL_WEIGHTS).state_dict()
    assert all(torch.equal(by_alias[k], by_path[k]) for k in by_path)
    default = load_network(None).state_dict()
    assert not all(torch.equal(default[k], by_path[k]) for k in by_path)  # the default is the project's own


@pytest.mark.parametrize("name", sorted(NAMED_WEIGHTS))
def test_every_named_weights_file_ships_small_safe_and_documented(name):
    """Each name ('' default, 'official', 'scan') is a package file under 5 MB that loads without pickle and says
    where it came from (its metadata, and a row of cemnet_ros/weights/README.md)."""
    path = NAMED_WEIGHTS[name]
    assert path.is_file() and path.stat().st_size < 5 * 1024 * 1024
    state, meta = load_weights(path, allow_pickle=False)
    assert meta and isinstance(load_network(name), SamplingNetwork)
    assert f"`{path.name}`" in (path.parent / "README.md").read_text()
