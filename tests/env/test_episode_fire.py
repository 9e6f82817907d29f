"""The fire an episode record reports (info["episode_fire"] beside the record): burning at the end and every cell
ever lit, checked against the fire's own cells at the end of an episode, before the env resets them."""

import numpy as np
import pytest
import torch

from roshan.config import Config, DroneConfig, FireConfig, IgnitionConfig, MapConfig, WindConfig
from roshan.env.fly import FlyVectorEnv
from roshan.kernels.fire import FireSim
from roshan.maps import BURNED, BURNING, FLOODED, load_map

# A small uniform map whose cells catch fire in 1 s and burn out after 3 s: in a few hundred steps the map holds
# burning, burned-out and unburned cells at once.
FAST = FireConfig(uniform_ignition_time=1.0, uniform_burning_time=3.0)


@pytest.mark.slow
def test_ever_lit_equals_the_final_cells_of_an_episode():
    cfg = Config(map=MapConfig(name="uniform", uniform_rows=16, uniform_cols=16), fire=FAST,
                 ignition=IgnitionConfig(fire_percentage=0.02), drones=DroneConfig(num_drones=1),
                 wind=WindConfig(speed=2.0))
    env = FlyVectorEnv(2, cfg, seed=3)
    env.reset(seed=3)
    zeros = torch.zeros((2, 1, 2))
    for _ in range(150):
        _, _, terms, truncs, _ = env.step(zeros)
        assert not bool((terms | truncs).any())
    # fly the drones off the map: a boundary exit ends both episodes two steps later
    env.drones.set_state(np.full((2, 1, 2), -500.0, np.float32), np.zeros((2, 1, 2), np.float32))
    for _ in range(4):
        env._advance(zeros)  # the step without the same-step reset: the cells are still the episode's last
        if bool(env._dones.any()):
            break
    ended = (env.terminations | env.truncations).nonzero().flatten().tolist()
    assert ended, "the drones left the map and no episode ended"
    cells = env.fire.states()  # the state of every cell
    n = env.fire.num_cells
    for e in ended:
        state = cells[e]
        assert env._info["episode_stats"]["extinguished"][e].item() == 0  # no water fell: no cell left the states
        burning, burned = int((state == BURNING).sum()), int((state == BURNED).sum())
        assert burning > 0 and burned > 0, "the scene should hold burning and burned-out cells"
        fire = env._info["episode_fire"]
        assert fire["lit_fraction"][e].item() * n == pytest.approx(burning + burned)
        assert fire["burning_fraction"][e].item() * n == pytest.approx(burning)
        assert env._info["episode_stats"]["burned_fraction"][e].item() * n == pytest.approx(burned)
    env.close()


def test_extinguished_cells_stay_counted_as_lit_after_the_flood_drains():
    # The final cell state cannot tell an extinguished cell: it is FLOODED, then its class again.
    sim = FireSim(load_map("uniform", rows=4, cols=4), fire=FAST,
                  ignition=IgnitionConfig(fire_percentage=0.0), wind=WindConfig(speed=0.0))
    sim.reset()
    mask = np.zeros((1, 16), np.int32)
    mask[0, [5, 6]] = 1
    sim.ignite_cells(mask)
    assert sim.lit_counts().tolist() == [2]
    out = np.zeros((1, 1), np.int32)
    sim.flood(np.array([[5]], np.int32), out)
    assert out[0, 0] == 1 and sim.state(0).reshape(-1)[5] == FLOODED
    sim.step(60)  # the flood drains (5 s); cell 6 burns out (3 s) and its neighbours catch fire (1 s)
    state = sim.state(0).reshape(-1)
    assert state[5] != FLOODED and state[6] == BURNED
    lit_now = int(((state == BURNING) | (state == BURNED)).sum())
    assert sim.lit_counts()[0] == lit_now + (0 if state[5] in (BURNING, BURNED) else 1)
    sim.reset()
    assert sim.lit_counts().tolist() == [0]


