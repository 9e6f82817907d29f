"""Physics invariants of the FireSPIN kernels, and the generator's patterns."""

import numpy as np
import pytest

from roshan.config import ConvectionConfig, FireConfig, IgnitionConfig, RadiationConfig, WindConfig
from roshan.kernels.fire import C_PERIODS, C_STATE, T_BURN_LEFT, T_IGN, FireSim
from roshan.maps import BURNED, BURNING, FLOODED, load_map
from tests.conftest import make_map

NO_PARTICLES = FireConfig(convection=ConvectionConfig(enabled=False), radiation=RadiationConfig(enabled=False))
NO_FIRE = IgnitionConfig(fire_percentage=0.0)


def ignite(sim, cells, env=None):
    """Ignite flat cell indices in one env (or all envs)."""
    mask = np.zeros((sim.num_envs, sim.num_cells), np.int32)
    envs = range(sim.num_envs) if env is None else [env]
    for e in envs:
        mask[e, cells] = 1
    sim.ignite_cells(mask)


def states(sim):
    return sim.states()


@pytest.mark.slow
def test_burned_cells_never_reignite_and_burning_cells_burn_out():
    sim = FireSim(load_map("21x21_Field"), ignition=IgnitionConfig(fire_percentage=0.2), num_envs=4, seed=3)
    sim.reset()
    burned_before = np.zeros((4, sim.num_cells), bool)
    for _ in range(40):
        sim.step(500)
        s = states(sim)
        assert np.all(s[burned_before] == BURNED), "a burned cell changed state"
        burned_before = s == BURNED
    assert burned_before.sum() > 100, "the test fire should burn a good part of the field"
    assert np.array_equal(sim.stats()["burned"], burned_before.sum(axis=1))


@pytest.mark.parametrize("barrier", [9, 10, 11, 15])
def test_barrier_classes_never_burn(barrier):
    rng = np.random.default_rng(barrier)
    classes = np.where(rng.random((24, 24)) < 0.3, barrier, 6)
    sim = FireSim(make_map(classes), ignition=IgnitionConfig(fire_percentage=0.2, pattern="scattered"),
                  num_envs=4, seed=1)
    sim.reset()
    is_barrier = (classes == barrier).reshape(-1)
    for _ in range(20):
        sim.step(1000)
        s = states(sim)
        assert np.all(s[:, is_barrier] == barrier)
    assert (states(sim) == BURNED).sum() > 50


def test_fire_does_not_cross_a_wide_water_channel():
    # Grass west of a 100 m channel; a strong wind blows east, straight at it (docs/model/fire.md §7: convection
    # particles drift ~10 m, radiation particles reach ~17 m on CLC+ classes).
    classes = np.full((30, 50), 6)
    classes[:, 20:30] = 10
    wind = WindConfig(speed=20.0, direction=90.0)
    sim = FireSim(make_map(classes), wind=wind, ignition=NO_FIRE, num_envs=3, seed=2)
    sim.reset()
    ignite(sim, [i * 50 + j for i in range(30) for j in range(15, 20)])
    for _ in range(20):
        sim.step(1000)
        east = states(sim).reshape(3, 30, 50)[:, :, 30:]
        assert not np.any((east == BURNING) | (east == BURNED))
    burned_west = (states(sim).reshape(3, 30, 50)[:, :, :20] == BURNED).sum()
    assert burned_west >= 3 * 30 * 5, "the lit strip itself must have burned"


def test_strong_wind_spreads_fire_further_downwind_than_upwind():
    n = 41
    classes = np.full((n, n), 6)
    sim = FireSim(make_map(classes), wind=WindConfig(speed=15.0, direction=90.0), ignition=NO_FIRE, num_envs=8,
                  seed=5)
    sim.reset()
    mid = n // 2
    ignite(sim, [i * n + j for i in range(mid - 2, mid + 3) for j in range(mid - 2, mid + 3)])
    sim.step(12000)
    s = states(sim).reshape(8, n, n)
    touched = (s == BURNING) | (s == BURNED)
    east = touched[:, :, mid + 3:].sum()
    west = touched[:, :, : mid - 2].sum()
    assert east > 2 * west + 10, (east, west)


@pytest.mark.slow
def test_a_burning_cell_burns_out_after_its_randomised_duration():
    sim = FireSim(make_map(np.full((5, 5), 2)), NO_PARTICLES, ignition=NO_FIRE, num_envs=6, seed=11)
    sim.reset()
    _, timers = sim.cell_records()
    durations = timers[:, 2, 2, T_BURN_LEFT]
    assert len(np.unique(durations.round(3))) > 1, "durations are randomised per env"
    assert np.all((durations >= 3600 * 0.8) & (durations <= 3600 * 1.2))
    expected = []
    for d in durations:  # the reference's double-precision countdown
        left, n = d, 0
        while left > 0:
            left -= 0.1
            n += 1
        expected.append(n)
    ignite(sim, [12])
    done = np.full(6, -1)
    step = 0
    while (done < 0).any():
        sim.step(1)
        step += 1
        burned = states(sim)[:, 12] == BURNED
        done[(done < 0) & burned] = step
    assert done.tolist() == expected


@pytest.mark.slow
def test_particles_die_out_once_nothing_burns():
    sim = FireSim(load_map("15x15_Woods"), ignition=IgnitionConfig(fire_percentage=0.05), num_envs=2, seed=4)
    sim.reset()
    sim.step(3000)
    assert sim.stats()["convection"].sum() > 0
    sim.flood(np.array([np.flatnonzero(states(sim)[e] == BURNING).tolist() + [-1] * 225
                        for e in range(2)], np.int32)[:, :225], np.zeros((2, 225), np.int32))
    assert sim.stats()["burning"].sum() == 0
    sim.step(2500)  # > the longest radiation life on CLC+ classes (~1700 updates)
    st = sim.stats()
    assert st["burning"].sum() == 0 and st["convection"].sum() == 0 and st["radiation"].sum() == 0


def test_flooding_extinguishes_then_the_cell_returns_to_its_class():
    sim = FireSim(make_map(np.full((6, 6), 6)), ignition=NO_FIRE, num_envs=1, seed=0)
    sim.reset()
    ignite(sim, [14])
    sim.step(400)  # long enough for convection particles
    out = np.zeros((1, 2), np.int32)
    sim.flood(np.array([[14, 15]], np.int32), out)
    assert out.tolist() == [[1, 0]]
    s = states(sim)[0]
    assert s[14] == FLOODED and s[15] == FLOODED
    conv, rad = sim.particles(0)
    cells = (conv[:, 0] // 10).astype(int) * 6 + (conv[:, 1] // 10).astype(int)
    assert not np.isin(cells, [14, 15]).any()
    sim.step(51)  # flood_duration 5 s: the double sum of 0.1 reaches 5 after 51 additions
    s = states(sim)[0]
    assert s[14] == 6 and s[15] == 6
    assert sim.stats()["extinguished"][0] == 1


@pytest.mark.slow
def test_pool_overflow_is_counted_not_silent():
    sim = FireSim(load_map("21x21_Field"), FireConfig(conv_capacity=3, rad_capacity=2),
                  ignition=IgnitionConfig(fire_percentage=0.3), num_envs=2, seed=1)
    sim.reset()
    sim.step(2000)
    st = sim.stats()
    assert np.all(st["convection"] <= 3) and np.all(st["radiation"] <= 2)
    assert st["dropped_convection"].sum() > 0


@pytest.mark.parametrize("pattern", ["cluster", "scattered", "ring"])
def test_generator_lights_the_requested_number_of_fires(pattern):
    land = load_map("54x71_Woods")
    pct = 0.05
    sim = FireSim(land, ignition=IgnitionConfig(fire_percentage=pct, pattern=pattern, clusters=3), num_envs=6,
                  seed=7)
    sim.reset()
    expected = int(np.float32(land.rows * land.cols) * np.float32(pct))
    assert sim.stats()["burning"].tolist() == [expected] * 6
    assert sim.stats()["initial_fires"].tolist() == [expected] * 6


@pytest.mark.slow
def test_thesis_era_generator_lights_at_most_the_requested_fires():
    # docs/model/fire.md §11: without re-seeding each cluster is a self-avoiding walk that stops when trapped. A port of
    # the thesis-era C++ generator lights a median of ~180-200 of the 441 fires (35 %, 2 clusters, 35x36_Woods).
    land = load_map("35x36_Woods")
    thesis = FireSim(land, ignition=IgnitionConfig(fire_percentage=0.35, reseed=False), num_envs=400, seed=11)
    thesis.reset()
    lit = thesis.stats()["initial_fires"]
    assert lit.max() <= 441 and 150 <= np.median(lit) <= 230 and 60 <= lit.std() <= 100
    newest = FireSim(land, ignition=IgnitionConfig(fire_percentage=0.35), num_envs=400, seed=11)
    newest.reset()
    assert newest.stats()["initial_fires"].tolist() == [441] * 400


def test_clusters_are_compact():
    land = load_map("54x71_Woods")
    sim = FireSim(land, ignition=IgnitionConfig(fire_percentage=0.05, clusters=1), num_envs=4, seed=3)
    sim.reset()
    for e in range(4):
        ij = np.argwhere(states(sim)[e].reshape(land.shape) == BURNING)
        span = ij.max(axis=0) - ij.min(axis=0) + 1
        assert span.prod() < 0.25 * land.rows * land.cols, "one cluster should not be scattered over the map"


@pytest.mark.slow
def test_fixed_wind_direction_gives_the_wind_vector():
    sim = FireSim(load_map("15x15_Woods"), wind=WindConfig(speed=8.0, direction=90.0), num_envs=2, seed=0)
    sim.reset()
    np.testing.assert_allclose(sim.wind_vectors(), [[0.0, 8.0], [0.0, 8.0]], atol=1e-5)
    rnd = FireSim(load_map("15x15_Woods"), wind=WindConfig(speed=8.0), num_envs=64, seed=0)
    rnd.reset()
    w = rnd.wind_vectors()
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 8.0, rtol=1e-5)
    angles = np.arctan2(w[:, 1], w[:, 0])
    assert np.histogram(angles, bins=4, range=(-np.pi, np.pi))[0].min() >= 5, "random directions cover the circle"


def test_uniform_map_takes_its_times_from_the_config():
    land = load_map("uniform", rows=10, cols=10)
    sim = FireSim(land, FireConfig(uniform_burning_time=50.0, uniform_ignition_time=20.0), ignition=NO_FIRE)
    sim.reset()
    _, timers = sim.cell_records()
    assert np.all((timers[..., 1] >= 40.0 - 1e-6) & (timers[..., 1] <= 60.0 + 1e-6))
    assert np.all((timers[..., 0] >= 16.0 - 1e-6) & (timers[..., 0] <= 24.0 + 1e-6))


@pytest.mark.slow
def test_cell_durations_are_the_same_whenever_they_are_drawn():
    # Durations are drawn when a cell is first exposed or lit, not at reset: the counter-based draw must give
    # the values an eager draw at reset gives, and a new episode must draw new ones.
    woods = load_map("35x36_Woods")
    eager = FireSim(woods, ignition=IgnitionConfig(fire_percentage=0.1), num_envs=4, seed=5)
    lazy = FireSim(woods, ignition=IgnitionConfig(fire_percentage=0.1), num_envs=4, seed=5)
    eager.reset()
    ints_eager, timers_eager = eager.cell_records()  # every cell drawn at t = 0
    lazy.reset()
    lazy.step(3000)
    stats = lazy.stats()
    spread = stats["burning"] + stats["burned"] - stats["initial_fires"]
    assert spread.sum() > 5, "cells must have been exposed and lit during the run"
    ints_lazy, timers_lazy = lazy.cell_records()
    np.testing.assert_array_equal(timers_lazy[..., T_IGN], timers_eager[..., T_IGN])
    np.testing.assert_array_equal(ints_lazy[..., C_PERIODS], ints_eager[..., C_PERIODS])
    unlit = (ints_lazy[..., C_STATE] != BURNING) & (ints_lazy[..., C_STATE] != BURNED)
    np.testing.assert_array_equal(timers_lazy[..., T_BURN_LEFT][unlit], timers_eager[..., T_BURN_LEFT][unlit])
    lazy.reset()
    _, timers_next = lazy.cell_records()
    assert np.mean(timers_next[..., T_BURN_LEFT] != timers_eager[..., T_BURN_LEFT]) > 0.5, "a new episode redraws"


@pytest.mark.slow
def test_a_simulator_whose_streams_restart_replays_a_fresh_one_with_that_seed():
    land = make_map(np.full((8, 8), 2))
    ignition = IgnitionConfig(fire_percentage=0.1, pattern="scattered")
    fresh = FireSim(land, ignition=ignition, num_envs=2, seed=5)
    fresh.reset()
    used = FireSim(land, ignition=ignition, num_envs=2, seed=1)
    for _ in range(3):  # episodes under another seed, then the new owner's seed
        used.reset()
        used.step(5)
    used.restart_streams(5)
    used.reset()
    np.testing.assert_array_equal(used.states(), fresh.states())
    np.testing.assert_array_equal(used.step(20), fresh.step(20))


def test_relabel_takes_a_map_of_the_same_shape_only():
    sim = FireSim(make_map(np.full((4, 4), 2)), ignition=IgnitionConfig(fire_percentage=0.0))
    renamed = make_map(np.full((4, 4), 2))
    sim.relabel(renamed)
    assert sim.land_map is renamed
    with pytest.raises(ValueError, match=r"\(5, 4\) cells, but this simulator was built for .*\(4, 4\)"):
        sim.relabel(make_map(np.full((5, 4), 2)))
