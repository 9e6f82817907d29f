"""Memory estimates before allocation (issue 32, item 6): the estimate of a FireSim, of an env's simulators and
buffers, the refusal over the memory available (one line from the CLI), and upper bounds of the capacities.

The "available memory" is monkeypatched small, so every refusal is cheap: nothing is allocated before it.
"""

import math
from pathlib import Path

import numpy as np
import pytest
import taichi as ti
import torch
from click.testing import CliRunner

from roshan import memory, runtime
from roshan.cli import main
from roshan.config import Config, ConfigError, DroneConfig, FireConfig, MapConfig, PlannerConfig, load_config
from roshan.env.fly import FlyVectorEnv
from roshan.env.planner import PlannerVectorEnv
from roshan.kernels import pool
from roshan.kernels.fire import FireSim
from roshan.kernels.fire_layout import fire_sizes
from roshan.maps import load_map, uniform_map

MODEL = str(Path(__file__).resolve().parents[1] / "models" / "fly_simple")
MiB = 2**20


@pytest.fixture
def available(monkeypatch):
    """Set the memory the checks see: ``available(bytes)``."""
    monkeypatch.delenv(memory.CHECK_ENV, raising=False)

    def set_to(n: int) -> None:
        monkeypatch.setattr(memory, "available_memory", lambda: (n, "a test's MemAvailable"))

    return set_to


def field_bytes(*objects) -> int:
    """Bytes of the Taichi fields and numpy arrays held as attributes of ``objects`` (each counted once)."""
    seen, total = set(), 0
    for obj in objects:
        for v in vars(obj).values():
            if id(v) in seen:
                continue
            if isinstance(v, ti.Field):
                seen.add(id(v))
                lanes = v.n * v.m if isinstance(v, ti.MatrixField) else 1
                item = np.dtype(ti.lang.util.to_numpy_type(v.dtype)).itemsize
                total += math.prod(v.shape) * lanes * item
            elif isinstance(v, np.ndarray):
                seen.add(id(v))
                total += v.nbytes
    return total


# ---------------------------------------------------------------------------------------------- available memory


def test_available_memory_is_memavailable_with_a_fallback(tmp_path, monkeypatch):
    monkeypatch.setattr(memory, "_cgroup_room", lambda: None)
    info = tmp_path / "meminfo"
    info.write_text("MemTotal:       24683568 kB\nMemFree:        18359000 kB\nMemAvailable:   20183100 kB\n")
    monkeypatch.setattr(memory, "MEMINFO", info)
    assert memory.available_memory() == (20183100 * 1024, "MemAvailable in /proc/meminfo")
    monkeypatch.setattr(memory, "MEMINFO", tmp_path / "missing")  # not Linux: free physical pages
    room, source = memory.available_memory()
    assert room > 0 and "sysconf" in source
    monkeypatch.setattr(memory, "_cgroup_room", lambda: 5 * MiB)  # a container's limit narrows it
    assert memory.available_memory() == (5 * MiB, "the room under this process's cgroup memory limit")


def test_check_fits_refuses_warns_and_can_be_turned_off(available, monkeypatch):
    available(100 * MiB)
    memory.check_fits("a build", 40 * MiB, ["fewer envs"])  # under half: silent
    with pytest.warns(UserWarning, match=r"a build will take an estimated 60\.0 MiB of the 100\.0 MiB"):
        memory.check_fits("a build", 60 * MiB, ["fewer envs"])
    with pytest.raises(memory.MemoryLimitError, match=r"^a build needs an estimated 95\.0 MiB of memory, but "
                                                       r"100\.0 MiB is available \(a test's MemAvailable\) and a build "
                                                       r"may take 90% of it; use fewer envs, or x"):
        memory.check_fits("a build", 95 * MiB, ["fewer envs", "x"])
    memory.check_fits("a build", 95 * MiB, ["fewer envs"], arch="cuda")  # a GPU's memory is not the host's
    monkeypatch.setenv(memory.CHECK_ENV, "0")
    memory.check_fits("a build", 10**15, ["fewer envs"])


# ---------------------------------------------------------------------------------------------- the estimates


@pytest.mark.parametrize("layout", ["dense", "sparse"])
def test_the_fire_estimate_is_every_byte_a_fire_sim_allocates(layout):
    land = load_map("Borkenberge") if layout == "sparse" else load_map("35x36_Woods")
    sim = FireSim(land, FireConfig(layout=layout), num_envs=3)
    assert sim.layout == layout
    assert sim.sizes.estimate_bytes() == field_bytes(sim)
    assert sim.sizes == fire_sizes(land.rows, land.cols, FireConfig(layout=layout), sim.ignition_cfg, 3)


def test_the_fire_estimate_counts_the_chunked_scratch():
    sim = FireSim(load_map("35x36_Woods"), FireConfig(parallel="chunks"), num_envs=2)
    assert sim.sizes.estimate_bytes(chunked=True) == field_bytes(sim, sim.chunked)


def _bundle_and_buffers(env) -> tuple[int, int]:
    """(bytes of the env's simulators, their host arrays and the pool's pristine copies; bytes of its torch
    buffers). Closes the env (its bundle goes back to the pool, where the copies are)."""
    sims = [env.fire, env.drones, env.kernels, *([env.explorers, env.maps] if hasattr(env, "maps") else [])]
    # every tensor the env owns: views (terminations, observation dicts) have a base and share its bytes
    buffers = sum(t.nbytes for t in vars(env).values() if isinstance(t, torch.Tensor) and t._base is None)
    env.close()
    entry = next(e for free in pool.current_pool().free.values() for e in free if e.sims.fire is env.fire)
    copies = type("Copies", (), {})()
    vars(copies).update({f"f{k}": f for k, f in enumerate(entry.pristine.saved)})
    return field_bytes(*sims) + field_bytes(copies), buffers


@pytest.mark.slow
def test_the_fly_env_estimate_matches_its_fields_and_buffers():
    cfg = Config(drones=DroneConfig(num_drones=3), map=MapConfig(name="21x21_Field"))
    env = FlyVectorEnv(5, cfg)
    buffers_estimate = env._buffer_bytes()
    sims, buffers = _bundle_and_buffers(env)
    assert buffers_estimate == buffers
    assert pool.fly_estimate(env.land, cfg, 5).bytes == sims


@pytest.mark.slow
def test_the_planner_env_estimate_matches_its_fields_and_buffers():
    cfg = Config(drones=DroneConfig(num_drones=2), map=MapConfig(name="21x21_Field"))
    pc = PlannerConfig(fly_model=MODEL, explorer_model=MODEL, num_explorers=2)
    env = PlannerVectorEnv(3, cfg, pc, evaluation=True)
    buffers_estimate = env._buffer_bytes()
    sims, buffers = _bundle_and_buffers(env)
    assert buffers_estimate == buffers
    # the waypoint table's length is estimated from paths that start at the corner cells' centres
    assert pool.planner_estimate(env.land, cfg, pc, 3).bytes == pytest.approx(sims, rel=0.01)


# ---------------------------------------------------------------------------------------------- refusals


def test_a_fire_sim_over_the_available_memory_is_refused_before_it_allocates(available):
    available(64 * MiB)
    trees = runtime.field_trees()
    with pytest.raises(memory.MemoryLimitError) as err:
        FireSim(load_map("35x36_Woods"), num_envs=1000)
    message = str(err.value)
    assert message.startswith("FireSim: 1,000 envs of map '35x36_Woods' (35 x 36 cells, dense layout) needs an "
                              "estimated ")
    assert "64.0 MiB is available (a test's MemAvailable)" in message
    assert "fewer envs (--envs / sim.envs)" in message and "fire.layout=sparse" in message
    assert "fire.conv_capacity / fire.rad_capacity (now 1,260 / 2,520 particles per env)" in message
    assert runtime.field_trees() == trees  # nothing was allocated


def test_100000_envs_of_the_941k_cell_map_are_refused(available):
    available(16 * 2**30)
    land = uniform_map(970, 970)
    need = fire_sizes(970, 970, FireConfig(), Config().ignition, 100_000).estimate_bytes()
    assert need > 500 * 2**30  # Taichi's own failure was a virtual allocation of 555 GiB
    match = r"100,000 envs of map 'uniform' \(970 x 970 cells, sparse layout\) needs an estimated [0-9.]+ GiB"
    with pytest.raises(memory.MemoryLimitError, match=match + r".*fire\.block_capacity"):
        FireSim(land, num_envs=100_000)


def test_a_fly_env_over_the_available_memory_is_refused_before_it_allocates(available):
    available(4 * MiB)
    trees = runtime.field_trees()
    with pytest.raises(memory.MemoryLimitError, match=r"^FlyVectorEnv \(simple policy\): 64 envs of map "
                                                      r"'35x36_Woods' .*, about [0-9.]+ KiB per env, needs an "
                                                      r"estimated [0-9.]+ MiB"):
        FlyVectorEnv(64, Config())
    assert runtime.field_trees() == trees


def test_a_planner_env_refusal_names_the_candidate_list(available):
    available(4 * MiB)
    pc = PlannerConfig(fly_model=MODEL, explorer_model=MODEL, num_explorers=2)
    with pytest.raises(memory.MemoryLimitError, match=r"PlannerVectorEnv \(greedy\): 64 envs .*a smaller "
                                                      r"planner\.max_candidates \(now 1,261 per env\)"):
        PlannerVectorEnv(64, Config(), pc, controller="greedy")


def test_simulate_refuses_with_one_line(available):
    available(8 * MiB)
    for drones in ([], ["--drones", "2"]):
        r = CliRunner().invoke(main, ["simulate", "--map", "35x36_Woods", "--envs", "64", "--steps", "1", "--quiet",
                                      *drones])
        assert r.exit_code == 1, r.output
        last = r.output.strip().splitlines()[-1]
        assert last.startswith("Error: ") and "needs an estimated" in last and "8.0 MiB is available" in last
        assert "Traceback" not in r.output


@pytest.mark.parametrize("key, value", [("fire.conv_capacity", "3e9"), ("fire.conv_capacity", "400000000"),
                                        ("fire.rad_capacity", "1e12"), ("fire.block_capacity", "1e9"),
                                        ("planner.max_candidates", "1e9")])
def test_huge_capacities_are_config_errors_naming_the_key_and_range(key, value):
    with pytest.raises(ConfigError, match=rf"{key} = [0-9]+ is out of range; expected a value in \[0, [0-9]+\]"):
        load_config(None, [f"{key}={value}"])
