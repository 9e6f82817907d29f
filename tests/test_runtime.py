"""The Taichi field-tree guard: a clear error before Taichi's unchecked 512-tree limit, and reset_taichi."""

import numpy as np
import pytest

from roshan import runtime
from roshan.kernels.fire import FireSim
from tests.conftest import make_map


def test_simulators_refuse_to_start_near_the_field_tree_limit(monkeypatch):
    FireSim(make_map(np.full((4, 4), 2)), num_envs=1)  # at least one tree exists now
    used = runtime.field_trees()
    assert used >= 1
    monkeypatch.setattr(runtime, "MAX_FIELD_TREES", used + runtime.TREE_HEADROOM - 1)
    with pytest.raises(RuntimeError, match=rf"FireSim: this process already holds {used} Taichi field trees"):
        FireSim(make_map(np.full((4, 4), 2)), num_envs=1)


def test_reset_taichi_frees_every_field_tree():
    for _ in range(3):
        FireSim(make_map(np.full((4, 4), 2)), num_envs=2).reset()
    before = runtime.field_trees()
    assert before >= 3
    runtime.reset_taichi()
    assert runtime.current_arch() is None
    sim = FireSim(make_map(np.full((4, 4), 2)), num_envs=2)  # initialises Taichi again
    sim.reset()
    assert runtime.current_arch() == "cpu" and 1 <= runtime.field_trees() < before
