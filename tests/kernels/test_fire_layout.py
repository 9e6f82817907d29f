"""The sparse cell layout (8 x 8 blocks from a per-env pool) against the dense one: the same fire, less memory."""

import numpy as np
import pytest

from roshan.config import FireConfig, IgnitionConfig
from roshan.kernels.fire import FireSim
from roshan.kernels.fire_layout import block_grid, choose_layout, default_block_capacity, dense_bytes_per_env
from roshan.kernels.fire_records import BLOCK_CELLS
from roshan.maps import BURNING, load_map
from tests.conftest import assert_same_fire, water_and_a_reset

DYNAMIC_STATS = ("burning", "burned", "convection", "radiation", "dropped_convection", "dropped_radiation",
                 "flooded", "extinguished", "initial_fires")


def run_with_water_and_a_reset(layout: str, pattern: str, **fire) -> FireSim:
    """Fire, water on two burning cells and one unburned cell per env, a reset of env 1, more fire."""
    sim = FireSim(load_map("54x71_Woods"), FireConfig(layout=layout, **fire),
                  ignition=IgnitionConfig(fire_percentage=0.05, pattern=pattern, clusters=2), num_envs=3, seed=11)
    water_and_a_reset(sim, (1200, 800, 600))
    return sim


@pytest.mark.slow
@pytest.mark.parametrize("pattern", ["cluster", "ring", "scattered"])
def test_the_sparse_layout_gives_the_dense_trajectory(pattern):
    dense = run_with_water_and_a_reset("dense", pattern)
    # The dense run's particle pools, so that only the layout differs.
    sparse = run_with_water_and_a_reset("sparse", pattern, conv_capacity=dense.conv_capacity,
                                        rad_capacity=dense.rad_capacity)
    assert (dense.layout, sparse.layout) == ("dense", "sparse")
    assert_same_fire(dense, sparse, DYNAMIC_STATS)  # "blocks" counts the sparse pool only
    d_stats, s_stats = dense.stats(), sparse.stats()
    assert np.all(s_stats["dropped_blocks"] == 0)
    assert np.all(s_stats["blocks"] > 0) and np.all(d_stats["blocks"] == 0)


@pytest.mark.slow
def test_memory_follows_the_footprint_and_a_reset_hands_the_blocks_back():
    sim = FireSim(load_map("81x129_Campsite"), FireConfig(layout="sparse"),
                  ignition=IgnitionConfig(fire_percentage=0.01), num_envs=2, seed=3)
    rows, cols = block_grid(sim.rows, sim.cols)
    sim.reset()
    at_reset = sim.stats()["blocks"]
    sim.step(3000)
    grown = sim.stats()["blocks"]
    assert np.all(grown > at_reset), "particles and spread touch new blocks"
    assert np.all(grown < rows * cols // 2), "a 1 % fire touches a minority of the map's blocks"
    sim.reset(np.array([1, 0], np.int32))
    after = sim.stats()["blocks"]
    assert after[0] < grown[0] and after[1] == grown[1]
    # A block given back holds nothing of the last episode: the env's fire is a fresh one.
    state = sim.states()[0]
    assert (state == BURNING).sum() == sim.stats()["initial_fires"][0]


@pytest.mark.slow
def test_a_full_block_pool_is_counted_not_silent():
    sim = FireSim(load_map("54x71_Woods"), FireConfig(layout="sparse", block_capacity=3),
                  ignition=IgnitionConfig(fire_percentage=0.05), num_envs=2, seed=1)
    sim.reset()
    sim.step(1000)
    stats = sim.stats()
    assert np.all(stats["blocks"] == 3)
    assert np.all(stats["dropped_blocks"] > 0)
    lit = (sim.states() == BURNING).sum(axis=1)
    assert np.all(lit <= 3 * BLOCK_CELLS)


def test_auto_layout_is_sparse_where_the_pool_is_small_and_dense_envs_would_not_fit():
    def auto(rows, cols, pct, envs=1):
        blocks = int(np.prod(block_grid(rows, cols)))
        return choose_layout("auto", rows * cols, default_block_capacity(blocks, int(rows * cols * pct)), envs)

    assert auto(35, 36, 0.015, 4096) == "dense"  # 25 blocks: the pool would be the whole map
    # Borkenberge: 54.6 MiB dense per env, so 18 envs fit in 1 GiB and 19 do not.
    assert auto(481, 758, 0.015, 18) == "dense" and auto(481, 758, 0.015, 19) == "sparse"
    assert auto(853, 1103, 0.015, 1) == "dense"  # one env of a big map runs faster dense
    assert auto(853, 1103, 0.015, 64) == "sparse"
    assert auto(853, 1103, 0.35, 64) == "dense"  # a 35 % fire reaches most blocks
    assert choose_layout("dense", 10**6, 64) == "dense" and choose_layout("sparse", 100, 64) == "sparse"


def test_dense_bytes_estimate_is_what_a_dense_env_holds():
    land = load_map("54x71_Woods")
    sim = FireSim(land, FireConfig(layout="dense"), num_envs=1)
    assert abs(sim.memory_bytes_per_env() - dense_bytes_per_env(land.rows * land.cols)) < 1024


def test_sparse_memory_per_env_meets_the_big_map_targets():
    sim = FireSim(load_map("Borkenberge"), FireConfig(layout="sparse"), ignition=IgnitionConfig(fire_percentage=0.015),
                  num_envs=1)
    dense = FireSim(load_map("Borkenberge"), FireConfig(layout="dense"),
                    ignition=IgnitionConfig(fire_percentage=0.015), num_envs=1)
    assert sim.layout == "sparse"
    assert sim.memory_bytes_per_env() <= 4 * 2**20 < dense.memory_bytes_per_env() / 10


def test_grouped_timers_read_and_write_as_one_vector_field_with_each_group_in_its_own_array():
    import taichi as ti
    from taichi.lang.field import ScalarField

    from roshan.kernels.fire_layout import grouped_vector_field
    from roshan.runtime import ensure_taichi

    ensure_taichi()
    groups = ((1, 2), (0, 3), (4,))
    grouped = grouped_vector_field(ti.f64, (2, 5), groups)

    @ti.kernel
    def fill():
        for e, r in ti.ndrange(2, 5):
            for k in ti.static(range(5)):
                grouped[e, r][k] = e * 100.0 + r * 10.0 + k

    fill()
    expected = (np.arange(2)[:, None, None] * 100.0 + np.arange(5)[None, :, None] * 10.0
                + np.arange(5)[None, None, :])
    assert np.array_equal(grouped.to_numpy(), expected)
    parents = [ScalarField(m).snode.parent().ptr.id for m in grouped._get_field_members()]
    assert parents[1] == parents[2] and parents[0] == parents[3]  # a group shares one array of records
    assert len({parents[1], parents[0], parents[4]}) == 3
    with pytest.raises(AssertionError):
        grouped_vector_field(ti.f64, (2, 5), ((0, 1), (1, 2)))  # a component twice, one missing
