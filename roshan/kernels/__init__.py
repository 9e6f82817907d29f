"""All per-cell, per-particle and per-drone work, as Taichi kernels batched over environments."""

# First: roshan.runtime makes Taichi's kernel definition and building cheaper, before any kernel here is defined.
from roshan import runtime  # noqa: F401
