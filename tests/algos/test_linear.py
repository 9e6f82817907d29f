"""The networks' Linear layer on the pinned OpenBLAS (roshan/algos/linear.py, roshan/reproducible.py)."""

import hashlib

import pytest
import torch
import torch.nn.functional as F

from roshan import reproducible
from roshan.algos import linear as linear_module
from roshan.algos.linear import Linear, gemm, linear


def rand(*shape, seed=0):
    return torch.randn(*shape, generator=torch.Generator().manual_seed(seed))


def digest(t: torch.Tensor) -> str:
    return hashlib.sha256(t.contiguous().numpy().tobytes()).hexdigest()[:12]


def test_the_suite_runs_the_pinned_gemm_with_one_thread_of_its_forced_kernels():
    lib = reproducible.gemm_library()
    assert linear_module.pinned()
    assert lib.core == reproducible.GEMM_CORE == "Haswell"
    assert lib._lib.scipy_openblas_get_num_threads() == 1


@pytest.mark.parametrize("trans_a,trans_b", [(False, False), (False, True), (True, False), (True, True)])
def test_gemm_is_the_matrix_product_for_every_transpose(trans_a, trans_b):
    a, b = rand(37, 53, seed=1), rand(53, 29, seed=2)
    want = (a.double() @ b.double()).float()
    got = gemm(a.T.contiguous() if trans_a else a, b.T.contiguous() if trans_b else b, trans_a, trans_b)
    assert got.shape == (37, 29)
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5)


def test_gemm_handles_empty_sides():
    assert gemm(torch.zeros(0, 5), torch.zeros(5, 3)).shape == (0, 3)
    assert torch.equal(gemm(torch.zeros(4, 0), torch.zeros(0, 3)), torch.zeros(4, 3))


def test_linear_and_its_gradients_match_a_float64_reference():
    layer = Linear(37, 53)
    x = rand(4, 3, 37, seed=3).requires_grad_()
    layer(x).square().sum().backward()
    ref = torch.nn.Linear(37, 53).double()
    ref.load_state_dict({k: v.double() for k, v in layer.state_dict().items()})
    x64 = x.detach().double().requires_grad_()
    out64 = ref(x64)
    out64.square().sum().backward()
    torch.testing.assert_close(layer(x).double(), out64, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(x.grad.double(), x64.grad, rtol=1e-4, atol=1e-4)
    torch.testing.assert_close(layer.weight.grad.double(), ref.weight.grad, rtol=1e-4, atol=1e-4)
    torch.testing.assert_close(layer.bias.grad.double(), ref.bias.grad, rtol=1e-4, atol=1e-4)


def test_a_layer_without_bias_and_a_frozen_input_take_only_the_gradients_asked_for():
    layer = Linear(8, 5, bias=False)
    x = rand(6, 8, seed=4)  # no grad wanted
    layer(x).sum().backward()
    torch.testing.assert_close(layer.weight.grad, torch.ones(6, 5).T @ x, rtol=1e-5, atol=1e-5)


def test_outside_the_mode_and_off_float32_cpu_it_is_torchs_own_linear(monkeypatch):
    layer = Linear(16, 7)
    x = rand(9, 16, seed=5)
    monkeypatch.setattr(linear_module, "pinned", lambda: False)
    assert torch.equal(layer(x), F.linear(x, layer.weight, layer.bias))
    monkeypatch.undo()
    double = layer.double()
    assert torch.equal(double(x.double()), F.linear(x.double(), double.weight, double.bias))


def test_the_pinned_products_are_pinned_bit_for_bit():
    """The same bits on every AVX2 CPU, Intel or AMD: the kernels and their blocking are the forced core type's.
    Shapes cover the update's (rows x 256 x 256, the weight gradient's long sum) and the kernels' edge tiles."""
    got = [digest(gemm(rand(4096, 256, seed=6), rand(256, 256, seed=7), trans_b=True)),
           digest(gemm(rand(8192, 256, seed=8), rand(8192, 64, seed=9), trans_a=True)),
           digest(gemm(rand(777, 333, seed=10), rand(333, 129, seed=11))),
           digest(linear(rand(5, 3, 4, seed=12), rand(7, 4, seed=13), rand(7, seed=14)))]
    assert got == PINS


PINS = ['9ba03ca5b8f8', '50e41db13382', '75405537f3c0', '8aaa191a574d']


def test_a_missing_pinned_blas_is_named(monkeypatch):
    reproducible.gemm_library.cache_clear()
    monkeypatch.setattr(reproducible, "GEMM_PACKAGE", "no_such_openblas")
    try:
        with pytest.raises(reproducible.ReproducibleModeError, match="no_such_openblas.*make install"):
            reproducible.gemm_library()
        assert "no_such_openblas" in reproducible.check()
    finally:
        monkeypatch.undo()
        reproducible.gemm_library.cache_clear()
    assert reproducible.gemm_library().core == "Haswell"
