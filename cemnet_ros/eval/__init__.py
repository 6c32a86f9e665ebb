"""Evaluation: the paper's pair protocol, registration metrics and classical baselines."""
from cemnet_ros.eval.protocol import ProtocolConfig, RegistrationPair, load_shapes, make_pair, protocol_pairs

__all__ = ["ProtocolConfig", "RegistrationPair", "load_shapes", "make_pair", "protocol_pairs"]
