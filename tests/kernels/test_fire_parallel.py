"""The chunked update (one env's lists cut into chunks over threads) against the env-serial one: bit for bit."""

import numpy as np
import pytest

from roshan.config import FireConfig, IgnitionConfig
from roshan.kernels.fire import FireSim
from roshan.kernels.fire_layout import CHUNKS_MIN_FIRES, choose_parallel
from roshan.kernels.fire_parallel import ChunkedStep
from roshan.maps import load_map
from tests.conftest import assert_same_fire, water_and_a_reset

ENVS = 3


def run(parallel: str, pct: float = 0.05, **fire) -> FireSim:
    """Fire, water on two burning cells and one unburned cell per env, a reset of env 1, more fire. The chunked
    run cuts lists into chunks of 8 items, so even this small map's lists span many chunks."""
    sim = FireSim(load_map("54x71_Woods"), FireConfig(parallel=parallel, **fire),
                  ignition=IgnitionConfig(fire_percentage=pct, clusters=2), num_envs=ENVS, seed=11)
    assert sim.parallel == parallel
    if parallel == "chunks":
        sim.chunked = ChunkedStep(sim, min_chunk=8)
    water_and_a_reset(sim, (4000, 2000, 1500))
    return sim


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["dense", "sparse"])
@pytest.mark.parametrize("pct", [0.05, 0.35])
def test_the_chunked_update_gives_the_serial_trajectory(layout, pct):
    serial = run("envs", pct, layout=layout)
    chunked = run("chunks", pct, layout=layout)
    stats = chunked.stats()
    assert np.any(chunked.lit_counts() > stats["initial_fires"]), "the fire must spread (exposure, ignition)"
    assert stats["convection"].sum() > 0 and stats["radiation"].sum() > 0
    assert_same_fire(serial, chunked)


@pytest.mark.slow
def test_full_pools_drop_the_same_emissions_and_blocks():
    """Pools too small for the fire: the chunked update drops exactly what the serial one drops."""
    small = {"layout": "sparse", "block_capacity": 12, "conv_capacity": 24, "rad_capacity": 24}
    serial = run("envs", 0.05, **small)
    chunked = run("chunks", 0.05, **small)
    stats = serial.stats()
    assert stats["dropped_convection"].sum() > 0 and stats["dropped_radiation"].sum() > 0
    assert stats["dropped_blocks"].sum() > 0
    assert_same_fire(serial, chunked)


def test_auto_chunks_only_huge_fires_with_idle_threads():
    assert choose_parallel("auto", 1, CHUNKS_MIN_FIRES, threads=2) == "chunks"
    assert choose_parallel("auto", 1, CHUNKS_MIN_FIRES - 1, threads=2) == "envs"
    assert choose_parallel("auto", 2, CHUNKS_MIN_FIRES, threads=2) == "envs"  # every thread has an env
    assert choose_parallel("auto", 1, CHUNKS_MIN_FIRES, threads=1) == "envs"
    assert choose_parallel("chunks", 64, 10, threads=1) == "chunks"


def test_the_chunked_scratch_is_one_env_whatever_the_batch():
    land = load_map("54x71_Woods")
    one = FireSim(land, FireConfig(parallel="chunks"), num_envs=1)
    four = FireSim(land, FireConfig(parallel="chunks"), num_envs=4)
    assert one.chunked.memory_bytes() == four.chunked.memory_bytes() > 0
    assert FireSim(land, FireConfig(parallel="envs"), num_envs=1).chunked is None
