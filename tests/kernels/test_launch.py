"""PreparedLaunch: a launch set up once does what the ordinary call does, and falls back where it cannot."""

import numpy as np
import taichi as ti
import torch

from roshan.kernels.launch import PreparedLaunch
from roshan.runtime import ensure_taichi


@ti.data_oriented
class Kernels:
    def __init__(self):
        self.total = ti.field(ti.f32, shape=())

    @ti.kernel
    def scale_add(self, x: ti.types.ndarray(dtype=ti.f32, ndim=2), out: ti.types.ndarray(dtype=ti.f32, ndim=2),
                  factor: ti.f32, offset: ti.i32, key: ti.u32, flags: ti.types.ndarray(dtype=ti.u8, ndim=1)):
        for i, j in ti.ndrange(x.shape[0], x.shape[1]):
            out[i, j] = x[i, j] * factor + offset + ti.cast(key % 7, ti.f32)
        for i in range(flags.shape[0]):
            flags[i] += ti.u8(1)
        self.total[None] += 1.0

    @ti.kernel
    def add_vectors(self, v: ti.types.ndarray(dtype=ti.math.vec2, ndim=1)):
        for i in range(v.shape[0]):
            v[i] += ti.math.vec2(1.0, 2.0)


def test_a_prepared_launch_writes_what_the_call_writes_and_follows_its_tensors():
    ensure_taichi()
    k = Kernels()
    x = torch.arange(12, dtype=torch.float32).reshape(3, 4)
    out, flags = torch.zeros(3, 4), np.zeros(5, np.uint8)
    launch = PreparedLaunch(k.scale_add, x, out, 1.5, -2, 4_000_000_001, flags)
    assert launch.prepared  # the CPU: calls skip Taichi's argument handling
    launch()
    expected = x * 1.5 - 2 + 4_000_000_001 % 7
    assert torch.equal(out, expected) and flags.tolist() == [1] * 5
    x.mul_(-1)  # the same memory, new values: the next launch reads them
    launch()
    assert torch.equal(out, x * 1.5 - 2 + 4_000_000_001 % 7) and flags.tolist() == [2] * 5
    assert k.total[None] == 2.0
    plain = torch.zeros(3, 4)
    k.scale_add(x, plain, 1.5, -2, 4_000_000_001, flags)
    assert torch.equal(plain, out)


def test_arguments_it_cannot_hold_fall_back_to_the_ordinary_call():
    ensure_taichi()
    k = Kernels()
    v = np.zeros((3, 2), np.float32)  # vector elements: Taichi strips their dims from the shape
    launch = PreparedLaunch(k.add_vectors, v)
    assert not launch.prepared
    launch()
    launch()
    assert v.tolist() == [[2.0, 4.0]] * 3
