"""Unsupervised training of the CEMNet sampling network (``cemnet-train``).

:mod:`.config` holds the recipe, :mod:`.data` the pair datasets, :mod:`.trainer` the loop,
:mod:`.distributed` the torch.distributed glue. Nothing here imports rclpy.
"""
from .config import TrainConfig

__all__ = ["TrainConfig"]
