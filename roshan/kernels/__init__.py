"""All per-cell, per-particle and per-drone work, as Taichi kernels batched over environments."""
