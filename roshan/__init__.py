"""ROSHAN-Taichi: batched FireSPIN wildfire simulation and hierarchical RL for UAV fire fighting.

Importing the package changes nothing in the process: no import hook, no allocator setting, no seeding. Those
happen where they are needed: :mod:`roshan.runtime` patches Taichi as it imports it and tunes the allocator when
it starts Taichi, and importing :mod:`roshan.env` registers the Gymnasium id ``roshan/FlyAgent-v0`` (so
``gymnasium.make("roshan.env:roshan/FlyAgent-v0")`` works in a fresh process, Gymnasium's own convention).
"""

__version__ = "0.1.0"
