"""The kernels' cell state machine against a small NumPy model of docs/model/fire.md §3-4 and §8.

Particles are off; exposure is prescribed (random cells "visited" each update) and water is dropped on random
cells, so every transition (exposure, pruning, ignition, burning, burn-out, flooding, flood end) is exercised.
"""

import numpy as np
import pytest

from roshan.config import ConvectionConfig, FireConfig, IgnitionConfig, RadiationConfig
from roshan.kernels.fire import T_BURN_LEFT, T_BURN_TIME, T_EXPOSURE, T_FLOOD, T_IGN, FireSim
from roshan.maps import BURNED, BURNING, CLASSES, FLOODED, LandCoverMap

DT = 0.1
FLOOD = 1.0


class NumpyCA:
    """The reference cell update, one env, sets instead of lists (order is irrelevant without particles)."""

    def __init__(self, land, tau_ign, tau_burn):
        self.land = land.copy()
        self.state = land.copy()
        self.tau_ign = tau_ign.copy()
        self.burn_left = tau_burn.copy()
        self.burn_time = np.zeros_like(tau_burn)
        self.exposure = np.zeros_like(tau_burn)
        self.flood_timer = np.zeros_like(tau_burn)
        self.burned_down = np.zeros(land.shape, bool)
        self.ignitable = np.array([c.is_ignitable for c in CLASSES])
        self.exposed, self.burning, self.flooded = set(), set(), set()

    def ignite(self, c):
        self.state[c] = BURNING
        self.burning.add(c)
        self.exposed.discard(c)

    def drop_water(self, c):
        was_burning = self.state[c] == BURNING
        if was_burning:
            self.burning.discard(c)
            self.exposure[c] = 0.0
        self.exposed.discard(c)
        self.flooded.add(c)
        self.state[c] = FLOODED
        self.flood_timer[c] = 0.0
        return int(was_burning)

    def step(self, visited):
        for c in np.flatnonzero(visited):  # 1. particles sit in these cells
            if self.ignitable[self.state[c]]:
                self.exposed.add(c)
        self.exposed = {c for c in self.exposed if visited[c]}  # 2. prune
        for c in sorted(self.flooded):  # 3. floods
            self.flood_timer[c] += DT
            if self.flood_timer[c] >= FLOOD:
                self.flood_timer[c] = FLOOD
                self.state[c] = BURNED if self.burned_down[c] else self.land[c]
                self.flooded.discard(c)
        for c in sorted(self.exposed):  # 4. exposure and ignition
            self.exposure[c] += DT
            if self.exposure[c] >= self.tau_ign[c]:
                self.ignite(c)
        for c in sorted(self.burning):  # 5. burning
            self.burn_time[c] += DT
            self.burn_left[c] -= DT
            if self.burn_left[c] <= 0:
                self.state[c] = BURNED
                self.burned_down[c] = True
                self.burning.discard(c)


@pytest.mark.slow
def test_kernel_cell_state_machine_matches_numpy_reference():
    rng = np.random.default_rng(42)
    rows, cols, envs = 12, 12, 2
    classes = np.full((rows, cols), 16, np.int32)
    classes[rng.random((rows, cols)) < 0.1] = 10  # water
    classes[rng.random((rows, cols)) < 0.05] = 9  # bare ground
    classes[0, :4] = 6  # a little grass with the class table's (long) times
    land = LandCoverMap(name="ref", classes=classes, cell_size=10.0, crs=None, transform=None, source=None,
                        is_uniform=True)
    fire = FireConfig(dt=DT, flood_duration=FLOOD, uniform_ignition_time=1.5, uniform_burning_time=4.0,
                      convection=ConvectionConfig(enabled=False), radiation=RadiationConfig(enabled=False))
    sim = FireSim(land, fire, ignition=IgnitionConfig(fire_percentage=0.0), num_envs=envs, seed=9)
    sim.reset()
    _, timers = sim.cell_records()
    n = rows * cols
    models = [NumpyCA(classes.reshape(-1), timers[e, ..., T_IGN].reshape(-1), timers[e, ..., T_BURN_LEFT].reshape(-1))
              for e in range(envs)]
    first = np.zeros((envs, n), np.int32)
    first[:, rng.choice(n, 6, replace=False)] = 1
    sim.ignite_cells(first)
    for e, m in enumerate(models):
        for c in np.flatnonzero(first[e]):
            if m.ignitable[m.state[c]]:
                m.ignite(c)
    seen = set()
    for t in range(600):
        if t % 40 == 39:  # drop water on a few cells, burning or not
            req = np.stack([rng.choice(n, 4, replace=False) for _ in range(envs)]).astype(np.int32)
            out = np.zeros_like(req)
            sim.flood(req, out)
            expected = [[m.drop_water(c) for c in req[e]] for e, m in enumerate(models)]
            assert out.tolist() == expected, f"update {t}"
        visited = (rng.random((envs, n)) < 0.35).astype(np.int32)
        sim.prescribe_exposure(visited)
        sim.step(1)
        for e, m in enumerate(models):
            m.step(visited[e].astype(bool))
        ints, timers = sim.cell_records()
        for e, m in enumerate(models):
            np.testing.assert_array_equal(ints[e, ..., 0].reshape(-1), m.state, err_msg=f"state, update {t}")
            tm = timers[e].reshape(n, -1)
            np.testing.assert_array_equal(tm[:, T_EXPOSURE], m.exposure, err_msg=f"exposure, update {t}")
            np.testing.assert_array_equal(tm[:, T_BURN_LEFT], m.burn_left, err_msg=f"burn_left, update {t}")
            np.testing.assert_array_equal(tm[:, T_BURN_TIME], m.burn_time, err_msg=f"burn_time, update {t}")
            busy = np.array(sorted(m.flooded), dtype=int)
            np.testing.assert_array_equal(tm[busy, T_FLOOD], m.flood_timer[busy], err_msg=f"flood, update {t}")
            seen.update(np.unique(m.state).tolist())
    assert {BURNING, BURNED, FLOODED, 16, 10, 9}.issubset(seen), "every transition must have been exercised"
