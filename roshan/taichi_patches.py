"""Patches to Taichi 1.7.4 (its last release) that cut the Python work of defining and building kernels.

This module imports nothing of Taichi: ``roshan/__init__.py`` applies :func:`patch_kernel_impl` the moment
``taichi.lang.kernel_impl`` has run, before ``import taichi`` goes on to define Taichi's own ~90 kernels and
functions (``taichi._funcs``, ``taichi._kernels``). Applied later, by :mod:`roshan.runtime`, it would leave
those to the slow path: ~60 ms of every start on this machine kind.

What is patched and why:
- to tell whether a ``@ti.kernel`` or ``@ti.func`` is defined in a class body, Taichi reads the class frame's
  source line with ``inspect.getframeinfo``, which scans ``sys.modules`` on every call. ``linecache`` reads the
  same line;
- it looks up a ti.func's source again (``inspect.getsourcefile`` / ``getsourcelines``, which scan
  ``sys.modules`` too) at every call site it inlines: ~900 lookups for a fire simulator. The source of a
  function object is looked up once.

tests/test_runtime.py holds both, and that a fresh ``import roshan, taichi`` makes no ``getframeinfo`` call.
"""

from __future__ import annotations

import linecache
import sys
from collections.abc import Callable


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
