"""Evaluation: simulators, metrics, the protocol."""
