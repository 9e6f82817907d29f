"""Shared fixtures: Taichi on the CPU once per session, and small maps built in code."""

import numpy as np
import pytest

from roshan.runtime import init_taichi, reset_taichi


@pytest.fixture(scope="module", autouse=True)
def taichi_cpu():
    """Taichi on the CPU, reset after each test module: the suite builds hundreds of envs, and one process
    holds at most 512 field trees (roshan.runtime.MAX_FIELD_TREES)."""
    init_taichi("cpu")
    yield
    reset_taichi()


def make_map(classes, name="test"):
    """A LandCoverMap from a 2-D array of class ids (10 m cells)."""
    from roshan.maps import LandCoverMap

    return LandCoverMap(name=name, classes=np.asarray(classes, dtype=np.int32), cell_size=10.0, crs=None,
                        transform=None, source=None)
