"""A kernel launch whose arguments are set once: the per-step launches of an env, whose tensors never change.

Taichi 1.7.4 rebuilds a kernel's launch context on every call: it extracts the template key of every argument
(a weak reference per data-oriented object, a dtype and shape check per tensor, an ``os.environ`` lookup per
tensor), looks the compiled kernel up and copies each tensor's pointer and shape into a new context. For the
FlyAgent step at E = 1 that Python work costs about twice the launch and the work together (BENCHMARKS,
"Start-up and one env"). An env's step kernel takes the same tensors at every step (its buffers; the actions are
copied into a buffer of their own), so :class:`PreparedLaunch` builds the context once and each call is the C++
launch alone.

Only on the CPU, and only for arguments the context holds by value or by host pointer (torch CPU tensors,
numpy arrays, Python scalars, template arguments): there Taichi's launcher reads the context and writes
nothing back into it, so one context serves every launch. Elsewhere (CUDA, Vulkan, Taichi ndarrays) a
:class:`PreparedLaunch` makes the ordinary call, whose result is the same.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from taichi._lib import core as ti_core
from taichi.lang import impl, kernel_impl
from taichi.lang.enums import Layout
from taichi.lang.util import cook_dtype
from taichi.types import ndarray_type, primitive_types
from taichi.types.utils import is_signed


class PreparedLaunch:
    """``launch()`` runs ``kernel(*args)``; the arguments must keep their memory (same tensors, same shapes)
    for as long as the launch is used."""

    def __init__(self, kernel: Callable, *args):
        self._kernel, self._args = kernel, args
        on_cpu = impl.current_cfg().arch in (ti_core.Arch.x64, ti_core.Arch.arm64)
        self._context = _fixed_context(kernel, args) if on_cpu else None

    @property
    def prepared(self) -> bool:
        """True where calls skip Taichi's argument handling (the CPU)."""
        return self._context is not None

    def __call__(self) -> None:
        if self._context is None:
            self._kernel(*self._args)
            return
        prog, compiled, context = self._context
        prog.launch_kernel(compiled, context)


def _fixed_context(kernel: Callable, args: tuple) -> tuple | None:
    """(program, compiled kernel, launch context) for ``kernel(*args)``, or None where an argument is of a kind
    the context does not hold by value or host pointer."""
    primal = getattr(kernel, "_primal", None)
    if not isinstance(primal, kernel_impl.Kernel) or getattr(kernel, "_is_staticmethod", True):
        return None
    full = kernel_impl._process_args(primal, (kernel._kernel_owner, *args), {})
    key = primal.ensure_compiled(*full)  # compiles on first use, as a call would
    t_kernel = primal.compiled_kernels[key]
    context = t_kernel.make_launch_context()
    slot = 0
    for value, argument in zip(full, primal.arguments, strict=True):
        annotation = argument.annotation
        if isinstance(annotation, kernel_impl.template):
            continue  # part of the compiled kernel's key, not of the context
        if not _set_argument(context, (slot,), annotation, value):
            return None
        slot += 1
    prog = impl.get_runtime().prog
    return prog, prog.compile_kernel(prog.config(), prog.get_device_caps(), t_kernel), context


def _set_argument(context, index: tuple[int], annotation, value) -> bool:
    """Write one argument into ``context`` as Taichi's own call does; False for a kind not handled here."""
    if id(annotation) in primitive_types.real_type_ids:
        context.set_arg_float(index, float(value))
        return True
    if id(annotation) in primitive_types.integer_type_ids:
        (context.set_arg_int if is_signed(cook_dtype(annotation)) else context.set_arg_uint)(index, int(value))
        return True
    if not isinstance(annotation, ndarray_type.NdarrayType) or annotation.layout == Layout.SOA:
        return False
    if annotation.dtype is not None and id(annotation.dtype) not in primitive_types.type_ids:
        return False  # vector or matrix elements: Taichi strips their dims from the shape
    if hasattr(value, "data_ptr") and hasattr(value, "is_contiguous"):  # a torch tensor (kernels/ imports no torch)
        if value.device.type != "cpu" or not value.is_contiguous() or value.requires_grad:
            return False
        pointer, nbytes = value.data_ptr(), value.element_size() * value.nelement()
    elif isinstance(value, np.ndarray) and value.flags.c_contiguous:
        pointer, nbytes = int(value.ctypes.data), value.nbytes
    else:
        return False
    context.set_arg_external_array_with_shape(index, pointer, nbytes, tuple(value.shape), 0)
    return True
