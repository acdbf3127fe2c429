"""Simulator and ground truth rules (synthetic datasets only)."""
