"""Shared fixtures: Taichi on the CPU once per session, and small maps built in code."""

import os

from roshan import reproducible

# The suite runs torch in the reproducible mode, as `roshan train` and `roshan eval` do by default: every pin that
# goes through a network holds on Intel and AMD alike. Set before torch loads (roshan/reproducible.py says why).
reproducible.enable()

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402

from roshan.runtime import init_taichi, reset_taichi  # noqa: E402

# One torch thread, here and in the subprocesses tests start. The tests' batches are tiny (a few drones), so a second
# thread gains nothing, and torch's OpenMP threads spin after each op on the cores Taichi's kernels need next: with
# two torch threads, a step of the endurance planner env (4 envs, collision fliers) took 475 ms beside two training
# runs, against 7.7 ms with one.
torch.set_num_threads(1)
os.environ.setdefault("OMP_NUM_THREADS", "1")

# The suite compiles its kernels without Taichi's advanced IR optimisation (``ti.init`` reads TI_ADVANCED_OPTIMIZATION,
# here and in the subprocesses tests start): with an empty offline cache, compiling is most of a test's time, and
# those passes are most of a compile (two test files took 434 s cold with them, 244 s without, AMD EPYC). The code
# they make computes the same: the behaviour pins, recorded under the default, hold under both, and the pins' module
# runs under the default (``COMPILE_AS_USERS_DO``), so the compile that users get stays covered.
FAST_COMPILE = {"TI_ADVANCED_OPTIMIZATION": "0"}
os.environ.update({k: os.environ.get(k, v) for k, v in FAST_COMPILE.items()})


@pytest.fixture(scope="module", autouse=True)
def taichi_cpu(request):
    """Taichi on the CPU, reset after each test module: the suite builds hundreds of envs, and one process
    holds at most 512 field trees (roshan.runtime.MAX_FIELD_TREES). A module that sets ``COMPILE_AS_USERS_DO``
    compiles with Taichi's defaults instead of the suite's fast compile."""
    as_users = getattr(request.module, "COMPILE_AS_USERS_DO", False)
    saved = {k: os.environ.pop(k, None) for k in FAST_COMPILE} if as_users else {}
    if as_users:
        reset_taichi()  # a runtime started before this module compiles fast
    init_taichi("cpu")
    yield
    reset_taichi()
    os.environ.update({k: v for k, v in saved.items() if v is not None})


def make_map(classes, name="test"):
    """A LandCoverMap from a 2-D array of class ids (10 m cells)."""
    from roshan.maps import LandCoverMap

    return LandCoverMap(name=name, classes=np.asarray(classes, dtype=np.int32), cell_size=10.0, crs=None,
                        transform=None, source=None)


def sim_with_fires(map_name: str, burning: list[tuple], num_envs: int = 1, seed: int = 1):
    """A FireSim of a bundled map with no random fires, reset, with the cells of ``burning`` lit: each entry
    indexes a (num_envs, rows, cols) mask, e.g. ``(0, 5, slice(5, 7))``."""
    from roshan.config import IgnitionConfig
    from roshan.kernels.fire import FireSim
    from roshan.maps import load_map

    init_taichi("cpu")
    s = FireSim(load_map(map_name), ignition=IgnitionConfig(fire_percentage=0.0), num_envs=num_envs, seed=seed)
    s.reset()
    mask = np.zeros((num_envs, s.rows, s.cols), np.int32)
    for index in burning:
        mask[index] = 1
    s.ignite_cells(mask.reshape(num_envs, -1))
    return s


def water_and_a_reset(sim, steps: tuple[int, int, int]) -> None:
    """Reset and run ``steps[0]`` updates; drop water on two burning cells and one fixed cell per env; run
    ``steps[1]``; reset env 1 alone; run ``steps[2]``: the events whose order a fire trajectory depends on."""
    sim.reset()
    sim.step(steps[0])
    burning, counts = sim.burning.to_numpy(), sim.stats()["burning"]
    requests = np.full((sim.num_envs, 3), -1, np.int32)
    for e in range(sim.num_envs):
        requests[e, : min(2, counts[e])] = burning[e, : min(2, counts[e])]
        requests[e, 2] = 7 * sim.cols + 3
    extinguished = np.zeros_like(requests)
    sim.flood(requests, extinguished)
    assert extinguished.sum() >= 3, "the drops must hit burning cells"
    sim.step(steps[1])
    reset = np.zeros(sim.num_envs, np.int32)
    reset[1] = 1
    sim.reset(reset)
    sim.step(steps[2])


def assert_same_fire(a, b, stats=None) -> None:
    """Two simulators hold the same fire: cell records, the statistics named in ``stats`` (default all), the
    particles in pool order and the burning, flooded and exposed lists in list order."""
    from roshan.kernels.fire_records import N_EXPOSED

    a_ints, a_timers = a.cell_records()
    b_ints, b_timers = b.cell_records()
    np.testing.assert_array_equal(a_ints, b_ints)
    np.testing.assert_array_equal(a_timers[..., :4], b_timers[..., :4])  # the flood timer is read only while flooded
    a_stats, b_stats = a.stats(), b.stats()
    for name in stats or a_stats:
        np.testing.assert_array_equal(a_stats[name], b_stats[name], err_msg=name)
    for e in range(a.num_envs):
        for x, y in zip(a.particles(e), b.particles(e), strict=True):
            np.testing.assert_array_equal(x, y)
    exposed = a.counts.to_numpy()[:, N_EXPOSED]
    np.testing.assert_array_equal(exposed, b.counts.to_numpy()[:, N_EXPOSED])
    lengths = {"burning": a_stats["burning"], "flooded": a_stats["flooded"], "exposed": exposed}
    for lst, n in lengths.items():
        a_list, b_list = getattr(a, lst).to_numpy(), getattr(b, lst).to_numpy()
        for e in range(a.num_envs):
            np.testing.assert_array_equal(a_list[e, : n[e]], b_list[e, : n[e]], err_msg=f"{lst} order, env {e}")
