"""Host-side checks of the arrays that callers hand to kernels (masks, requests): shape and dtype, once."""

import numpy as np


def int32_array(x, shape: tuple, what: str, copy_ok: bool = True):
    """Check an int array's shape (``None`` = any length there); numpy inputs become contiguous int32 (torch
    tensors must already be). ``copy_ok=False``: the kernel writes into ``x``, so a copy would lose its output."""
    got = tuple(x.shape)
    if len(got) != len(shape) or any(want is not None and g != want for g, want in zip(got, shape, strict=True)):
        want = tuple("M" if w is None else w for w in shape)
        raise ValueError(f"{what}: expected shape {want}, got {got}")
    if isinstance(x, np.ndarray):
        if not copy_ok and (x.dtype != np.int32 or not x.flags.c_contiguous):
            raise ValueError(f"{what}: expected a C-contiguous int32 array (written in place)")
        return np.ascontiguousarray(x, dtype=np.int32)
    return x
