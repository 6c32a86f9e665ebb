"""The CEMNet engine on numpy arrays and torch tensors. Never imports rclpy.

The configs import without torch (the node declares its parameters before the engine loads); the engine's
names load torch on first use.
"""
from .config import CEMConfig, EngineConfig, RegistrationConfig

__all__ = ["BatchRegistrationResult", "CEMConfig", "EngineConfig", "RegistrationConfig", "Registrar",
           "RegistrationResult", "register"]


def __getattr__(name: str):
    if name in ("BatchRegistrationResult", "Registrar", "RegistrationResult", "register"):
        from . import registration

        return getattr(registration, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
