"""The networks' Linear layer: in the reproducible mode its products run on the pinned OpenBLAS.

A FlyAgent update is three quarters matrix products. In the reproducible mode torch's own products (MKL) run its
slow vendor-neutral branch; :class:`Linear` sends them instead to the pinned OpenBLAS of
:func:`roshan.reproducible.gemm_library`, whose forced AVX2 kernels round alike on every CPU and run about three
times as fast. Outside the mode, and for what that BLAS does not take (tensors off the CPU, other dtypes), it is
``nn.Linear``. Parameters and checkpoints are ``nn.Linear``'s.
"""

from __future__ import annotations

import functools

import torch
import torch.nn.functional as F
from torch import nn

from roshan import reproducible


class Linear(nn.Linear):
    """``nn.Linear`` whose products, in the reproducible mode, run on the pinned BLAS (:func:`linear`)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return linear(x, self.weight, self.bias)


def linear(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None = None) -> torch.Tensor:
    """``F.linear``; in the reproducible mode, for float32 CPU tensors, on the pinned BLAS."""
    if not (pinned() and x.dtype == weight.dtype == torch.float32 and x.device.type == weight.device.type == "cpu"):
        return F.linear(x, weight, bias)
    return PinnedLinear.apply(x, weight, bias)


@functools.cache
def pinned() -> bool:
    """Whether this process runs the reproducible mode (decided once: torch's kernels are fixed at its first use)."""
    return reproducible.mode() == reproducible.MODES[0]


def gemm(a: torch.Tensor, b: torch.Tensor, trans_a: bool = False, trans_b: bool = False) -> torch.Tensor:
    """``op(a) @ op(b)`` for contiguous float32 CPU matrices on the pinned BLAS, ``op`` transposing where asked."""
    lib = reproducible.gemm_library()
    m, k = (a.shape[1], a.shape[0]) if trans_a else a.shape
    n = b.shape[0] if trans_b else b.shape[1]
    out = torch.empty((m, n), dtype=torch.float32)
    if m and n:
        if k == 0:
            return out.zero_()
        lib.sgemm(lib.ROW_MAJOR, lib.TRANS if trans_a else lib.NO_TRANS, lib.TRANS if trans_b else lib.NO_TRANS,
                  m, n, k, 1.0, a.data_ptr(), a.shape[1], b.data_ptr(), b.shape[1], 0.0, out.data_ptr(), n)
    return out


class PinnedLinear(torch.autograd.Function):
    """``x @ weight.T + bias`` with its gradients, every product on the pinned BLAS."""

    @staticmethod
    def forward(ctx, x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None) -> torch.Tensor:
        rows = x.detach().reshape(-1, x.shape[-1]).contiguous()
        w = weight.detach().contiguous()
        ctx.save_for_backward(rows, w)
        ctx.in_shape, ctx.has_bias = x.shape, bias is not None
        out = gemm(rows, w, trans_b=True)
        if bias is not None:
            out += bias.detach()
        return out.view(*x.shape[:-1], w.shape[0])

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        rows, w = ctx.saved_tensors
        g = grad.reshape(-1, grad.shape[-1]).contiguous()
        grad_x = grad_w = grad_b = None
        if ctx.needs_input_grad[0]:
            grad_x = gemm(g, w).view(ctx.in_shape)
        if ctx.needs_input_grad[1]:
            grad_w = gemm(g, rows, trans_a=True)
        if ctx.has_bias and ctx.needs_input_grad[2]:
            grad_b = g.sum(0)
        return grad_x, grad_w, grad_b
