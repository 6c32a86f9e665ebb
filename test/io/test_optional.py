"""matplotlib and Pillow are optional: without them the outputs that need them say so (what needs the library and
how to install it), and nothing else stops."""
import sys

import numpy as np
import pytest

from cemnet_ros.io.optional import MissingOptional, optional_module


@pytest.fixture
def without(monkeypatch):
    """Make a library and its submodules fail to import, as where it is not installed."""
    def block(*names):
        for name in names:
            monkeypatch.setitem(sys.modules, name, None)  # `import name` raises ImportError
    return block


def test_a_missing_library_names_what_needs_it_and_how_to_install_it(without):
    without("matplotlib", "matplotlib.figure")
    with pytest.raises(MissingOptional, match=r"the figure needs matplotlib.*apt install python3-matplotlib.*"
                                              r"pip install matplotlib"):
        optional_module("matplotlib.figure", "the figure")
    assert issubclass(MissingOptional, ImportError)


def test_the_replay_figure_without_matplotlib(without, tmp_path):
    from cemnet_ros.replay.plot import save_replay_plot

    without("matplotlib", "matplotlib.figure")
    with pytest.raises(MissingOptional, match=r"replay\.png"):
        save_replay_plot(tmp_path / "replay.png", np.stack([np.eye(4)] * 3))
    assert not (tmp_path / "replay.png").exists()


def test_training_curves_without_matplotlib_warn_and_skip(without, tmp_path):
    from cemnet_ros.train.outputs import write_curves

    without("matplotlib", "matplotlib.pyplot")
    with pytest.warns(RuntimeWarning, match=r"curves\.png not written: .*python3-matplotlib"):
        write_curves(tmp_path, [{"epoch": 1, "train_loss": 1.0}])
    assert not (tmp_path / "curves.png").exists()


def test_depth_images_without_pillow(without, tmp_path):
    from cemnet_ros.data.rgbd import read_depth_png

    without("PIL", "PIL.Image")
    with pytest.raises(MissingOptional, match=r"7-Scenes depth PNGs needs PIL.*python3-pil.*pip install pillow"):
        read_depth_png(tmp_path / "frame-000000.depth.png")
