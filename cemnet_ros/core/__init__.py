"""The CEMNet engine on numpy arrays and torch tensors. Never imports rclpy."""
from .config import CEMConfig, RegistrationConfig
from .registration import Registrar, RegistrationResult, register

__all__ = ["CEMConfig", "RegistrationConfig", "Registrar", "RegistrationResult", "register"]
