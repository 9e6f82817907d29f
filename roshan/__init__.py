"""ROSHAN-Taichi: batched FireSPIN wildfire simulation and hierarchical RL for UAV fire fighting."""

__version__ = "0.1.0"
