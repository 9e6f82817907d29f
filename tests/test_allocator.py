"""The glibc tuning that keeps large torch temporaries from being page-faulted in on every step."""

import platform

import pytest

from roshan import allocator


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt is glibc's")
def test_thresholds_are_raised_on_glibc(monkeypatch):
    monkeypatch.delenv("ROSHAN_MALLOC_TUNING", raising=False)
    assert allocator.retain_freed_memory() is True


def test_the_switch_leaves_the_defaults(monkeypatch):
    monkeypatch.setenv("ROSHAN_MALLOC_TUNING", "0")
    assert allocator.retain_freed_memory() is False
