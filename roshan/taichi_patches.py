"""Patches to Taichi 1.7.4 (its last release) that cut the Python work of defining and building kernels.

This module imports nothing of Taichi until asked: :func:`import_taichi`, which :mod:`roshan.runtime` calls before
anything of Taichi is imported, applies :func:`patch_kernel_impl` the moment ``taichi.lang.kernel_impl`` has run,
before ``import taichi`` goes on to define Taichi's own ~90 kernels and functions (``taichi._funcs``,
``taichi._kernels``). Applied after ``import taichi``, it would leave those to the slow path: ~60 ms of every start
on this machine kind. The one-shot import hook that does this is gone again when ``import_taichi`` returns.

What is patched and why:
- to tell whether a ``@ti.kernel`` or ``@ti.func`` is defined in a class body, Taichi reads the class frame's
  source line with ``inspect.getframeinfo``, which scans ``sys.modules`` on every call. ``linecache`` reads the
  same line;
- it looks up a ti.func's source again (``inspect.getsourcefile`` / ``getsourcelines``, which scan
  ``sys.modules`` too) at every call site it inlines: ~900 lookups for a fire simulator. The source of a
  function object is looked up once.

tests/test_runtime.py holds both, and that a fresh ``import roshan.runtime`` makes no ``getframeinfo`` call.
"""

from __future__ import annotations

import importlib.util
import linecache
import sys
from collections.abc import Callable

KERNEL_IMPL = "taichi.lang.kernel_impl"


def import_taichi():
    """``import taichi`` with the patches in place before Taichi defines its own kernels; the taichi module.

    Where Taichi is loaded already (a user imported it first), it is patched now. No import hook outlives the call.
    """
    if KERNEL_IMPL in sys.modules:
        patch_kernel_impl(sys.modules[KERNEL_IMPL])
    else:
        hook = _AfterImport(KERNEL_IMPL, patch_kernel_impl)
        try:
            import taichi  # noqa: F401
        finally:
            hook.remove()  # still there only if the import failed before reaching kernel_impl
    return sys.modules["taichi"]


class _AfterImport:
    """A one-shot import hook (a meta path finder and the loader it hands out; importlib.abc's base classes are
    left out because importing them costs 30 ms): finds module ``name`` with the other finders, runs it, then
    calls ``then(module)``."""

    def __init__(self, name: str, then: Callable):
        self.name, self.then = name, then
        sys.meta_path.insert(0, self)

    def remove(self) -> None:
        if self in sys.meta_path:
            sys.meta_path.remove(self)

    def find_spec(self, name, path, target=None):
        if name != self.name:
            return None
        self.remove()
        spec = importlib.util.find_spec(name)  # the finders after this one
        if spec is None or spec.loader is None:
            return spec
        self.loader, spec.loader = spec.loader, self
        return spec

    def create_module(self, spec):
        return self.loader.create_module(spec)

    def exec_module(self, module):
        module.__loader__ = module.__spec__.loader = self.loader  # the module keeps its own loader afterwards
        self.loader.exec_module(module)
        self.then(module)


def patch_kernel_impl(kernel_impl) -> None:
    """Install the patches in ``taichi.lang.kernel_impl`` (once; a second call does nothing)."""
    if hasattr(kernel_impl.getsourcelines, "uncached"):
        return
    kernel_impl.getsourcefile = _once_per_function(kernel_impl.getsourcefile)
    kernel_impl.getsourcelines = _once_per_function(kernel_impl.getsourcelines)
    kernel_impl._inside_class = _class_body_test(tuple(kernel_impl._KERNEL_CLASS_STACKFRAME_STMT_RES))


def _class_body_test(statements: tuple) -> Callable[[int], bool]:
    """Taichi's ``kernel_impl._inside_class`` with the frame's line read by linecache (what getframeinfo returns
    as its context line, without looking up the frame's module). It replaces the original in place, so the
    frame it looks at is the same; ``statements`` are Taichi's patterns of a class-body line."""

    def inside_class(level_of_class_stackframe: int) -> bool:
        try:
            frame = sys._getframe(level_of_class_stackframe)
            line = linecache.getline(frame.f_code.co_filename, frame.f_lineno).strip()
        except ValueError:  # no frame that deep
            return False
        return any(p.match(line) for p in statements)

    return inside_class


def _once_per_function(lookup: Callable) -> Callable:
    found: dict = {}  # function object -> what lookup returned for it

    def cached(func):
        if func not in found:
            found[func] = lookup(func)
        return found[func]

    cached.uncached = lookup
    return cached
