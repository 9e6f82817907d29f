"""Benchmarks behind ``roshan bench``: fire-model fidelity against the reference statistics, and speed."""

import csv
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from roshan.algos.agents import fly_ppo, make_agent
from roshan.algos.frozen import load_agent
from roshan.algos.networks import flatten_drones
from roshan.config import (
    Config,
    DroneConfig,
    FireConfig,
    FlyConfig,
    IgnitionConfig,
    MapConfig,
    PPOConfig,
    SimConfig,
    WindConfig,
    load_run_config,
)
from roshan.env.fly import FlyVectorEnv
from roshan.kernels.fire import FireSim
from roshan.maps import LandCoverMap, load_map
from roshan.runs.envs import make_env
from roshan.runs.learners import PPOLearner
from roshan.runtime import init_taichi

REFERENCE_QUANTITIES = ("burning", "burned", "convection", "radiation")


@dataclass(frozen=True)
class FidelityCondition:
    """One reference condition: a map and an ignition fraction (2 clusters, cluster pattern)."""

    name: str  # the reference CSV's stem
    map: str
    fire_percentage: float


FIDELITY_CONDITIONS = (
    FidelityCondition("uniform50_p0015", "uniform", 0.015),
    FidelityCondition("woods35x36_p0015", "35x36_Woods", 0.015),
    FidelityCondition("woods35x36_p035", "35x36_Woods", 0.35),
    FidelityCondition("campsite_p0015", "81x129_Campsite", 0.015),
    FidelityCondition("field21_p005", "21x21_Field", 0.05),
)


def reference_dir() -> Path:
    """Where the reference CSVs live: $ROSHAN_REFERENCE if set, else the copy bundled with the package."""
    env = os.environ.get("ROSHAN_REFERENCE")
    folder = Path(env) if env else Path(__file__).resolve().parents[1] / "data" / "reference"
    if not (folder / "woods35x36_p0015.csv").exists():
        raise FileNotFoundError(f"{folder}: no reference CSVs (woods35x36_p0015.csv, ...); set ROSHAN_REFERENCE")
    return folder


def load_reference(name: str, folder: Path | None = None) -> dict[str, np.ndarray]:
    """Reference statistics: ``step`` and ``<quantity>_{mean,min,max}`` arrays, one entry per checkpoint."""
    path = (folder or reference_dir()) / f"{name}.csv"
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    out = {"step": np.array([int(r["step"]) for r in rows])}
    for q in REFERENCE_QUANTITIES:
        for s in ("mean", "min", "max"):
            out[f"{q}_{s}"] = np.array([float(r[f"{q}_{s}"]) for r in rows])
    return out


def run_condition(cond: FidelityCondition, seeds: int, steps: np.ndarray, seed: int = 0) -> dict[str, np.ndarray]:
    """Run ``seeds`` independent envs of one condition in one batch; (checkpoints, seeds) arrays per quantity."""
    cfg = Config(map=MapConfig(name=cond.map), ignition=IgnitionConfig(fire_percentage=cond.fire_percentage))
    land = load_map(cfg.map.name)
    sim = FireSim(land, cfg.fire, cfg.wind, cfg.ignition, num_envs=seeds, seed=seed)
    sim.reset()
    out = {q: np.zeros((len(steps), seeds)) for q in REFERENCE_QUANTITIES}
    done = 0
    for k, target in enumerate(steps):
        sim.step(int(target) - done)
        done = int(target)
        stats = sim.stats()
        for q in REFERENCE_QUANTITIES:
            out[q][k] = stats[q]
    return out


def fidelity(seeds: int = 20, conditions=FIDELITY_CONDITIONS, from_step: int = 5000, seed: int = 0,
             progress: bool = True) -> dict:
    """Compare our seed means with the reference's seed band at every checkpoint.

    Returns a dict per condition with the checkpoint table and two verdicts: ``in_band`` (our mean inside the
    reference min..max at every checkpoint from ``from_step`` on, per quantity) and ``peak_ratio`` (our peak
    mean particle count over the reference's, per particle type).
    """
    results = {}
    for cond in conditions:
        ref = load_reference(cond.name)
        t0 = time.perf_counter()
        ours = run_condition(cond, seeds, ref["step"], seed=seed)
        elapsed = time.perf_counter() - t0
        rows, in_band = [], {}
        late = ref["step"] >= from_step
        for q in REFERENCE_QUANTITIES:
            mean = ours[q].mean(axis=1)
            inside = (mean >= ref[f"{q}_min"]) & (mean <= ref[f"{q}_max"])
            in_band[q] = bool(inside[late].all())
        for k, step in enumerate(ref["step"]):
            row = {"step": int(step)}
            for q in REFERENCE_QUANTITIES:
                row[q] = {"ours_mean": float(ours[q][k].mean()), "ours_min": float(ours[q][k].min()),
                          "ours_max": float(ours[q][k].max()), "ref_mean": float(ref[f"{q}_mean"][k]),
                          "ref_min": float(ref[f"{q}_min"][k]), "ref_max": float(ref[f"{q}_max"][k])}
            rows.append(row)
        peak = {q: float(ours[q].mean(axis=1).max() / max(ref[f"{q}_mean"].max(), 1e-9))
                for q in ("convection", "radiation")}
        results[cond.name] = {"map": cond.map, "fire_percentage": cond.fire_percentage, "seeds": seeds,
                              "in_band": in_band, "peak_ratio": peak, "rows": rows, "seconds": elapsed}
        if progress:
            print(format_fidelity_verdict(cond.name, results[cond.name]), flush=True)
    return results


def format_fidelity_verdict(name: str, res: dict) -> str:
    band = ", ".join(f"{q} {'ok' if v else 'OUT'}" for q, v in res["in_band"].items())
    peak = ", ".join(f"{q} x{v:.2f}" for q, v in res["peak_ratio"].items())
    return f"{name}: in band from 5000 steps: {band}; peak particles ours/ref: {peak} ({res['seconds']:.0f} s)"


def format_fidelity_table(name: str, res: dict, every: int = 5000) -> str:
    """Checkpoint table: ours mean [min..max] vs reference mean [min..max], per quantity."""
    head = f"{'step':>6} " + " ".join(f"{q + ' ours / ref':>30}" for q in REFERENCE_QUANTITIES)
    lines = [f"== {name} ({res['map']}, {res['fire_percentage'] * 100:g} %, {res['seeds']} seeds)", head]
    for row in res["rows"]:
        if row["step"] % every:
            continue
        cells = []
        for q in REFERENCE_QUANTITIES:
            r = row[q]
            mark = " " if r["ref_min"] <= r["ours_mean"] <= r["ref_max"] else "!"
            cells.append(f"{r['ours_mean']:8.1f}{mark}/{r['ref_mean']:7.1f} [{r['ref_min']:.0f}..{r['ref_max']:.0f}]")
        lines.append(f"{row['step']:>6} " + " ".join(f"{c:>30}" for c in cells))
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------- speed

# The original's fire model, one env, one thread, on this machine kind (shared/reference/README.md).
ORIGINAL_STEPS_PER_S = {
    ("35x36_Woods", 0.015): 430_000,
    ("35x36_Woods", 0.35): 50_000,
    ("81x129_Campsite", 0.015): 40_000,
    ("Borkenberge", 0.015): 1_500,
    ("Borkenberge_940k", 0.015): 500,  # the original's figure for Haard (941k cells)
}


HAARD_SHAPE = (853, 1103)  # the original's biggest map (941k cells), which is not bundled


def tiled_map(name: str = "Borkenberge", shape: tuple[int, int] = HAARD_SHAPE):
    """A ``shape`` map made by tiling a bundled map (mirrored, so tiles join without seams); by default Haard's
    size, whose figure the original reports."""
    base = load_map(name)
    a = base.classes
    reps_r, reps_c = -(-shape[0] // a.shape[0]), -(-shape[1] // a.shape[1])
    row = np.concatenate([a if k % 2 == 0 else a[:, ::-1] for k in range(reps_c)], axis=1)
    grid = np.concatenate([row if k % 2 == 0 else row[::-1] for k in range(reps_r)], axis=0)
    cells = shape[0] * shape[1]
    return LandCoverMap(name=f"{name}_{cells // 1000}k", classes=np.ascontiguousarray(grid[: shape[0], : shape[1]]),
                        cell_size=base.cell_size, crs=base.crs, transform=None, source=None)


def time_fire(land, fire_percentage: float, envs: int, steps: int, warmup: int, seed: int = 0) -> dict:
    """Time ``steps`` updates of ``envs`` envs after a reset and ``warmup`` untimed updates.

    Particles, wind (random direction) and the default capacities are on; the reset before the timed steps
    is timed too (every env resets once per run). Burning-cell updates are summed from 10 chunks.
    """
    cfg = Config(ignition=IgnitionConfig(fire_percentage=fire_percentage), sim=SimConfig(envs=envs, seed=seed))
    sim = FireSim(land, cfg.fire, WindConfig(), cfg.ignition, num_envs=envs, seed=seed)
    sim.reset()
    sim.step(max(warmup, 1))  # compiles the kernels
    sim.stats()
    chunks = 10
    per_chunk = max(1, steps // chunks)
    burning_updates = 0.0
    t0 = time.perf_counter()
    sim.reset()
    for _ in range(chunks):
        before = sim.counts.to_numpy()[:, 0].sum()
        sim.step(per_chunk)
        after = sim.counts.to_numpy()[:, 0].sum()
        burning_updates += 0.5 * (before + after) * per_chunk
    elapsed = time.perf_counter() - t0
    total = per_chunk * chunks * envs
    stats = sim.stats()
    return {"map": land.name, "cells": land.rows * land.cols, "fire_percentage": fire_percentage, "envs": envs,
            "steps": per_chunk * chunks, "seconds": elapsed, "env_steps_per_s": total / elapsed,
            "burning_cell_updates_per_s": burning_updates / elapsed,
            "mean_burning_end": float(stats["burning"].mean()),
            "particles_end": float((stats["convection"] + stats["radiation"]).mean()),
            "dropped": int(stats["dropped_convection"].sum() + stats["dropped_radiation"].sum()),
            "layout": sim.layout, "dropped_blocks": int(stats["dropped_blocks"].sum()),
            "memory_bytes_per_env": sim.memory_bytes_per_env()}


def fire_speed(env_counts=(1, 16, 64, 256, 1024), steps: int = 50_000, warmup: int = 100, big: bool = True,
               arch: str = "cpu", threads: int | None = None, on_row=None) -> dict:
    """The fire benchmark of BENCHMARKS.md: 35x36_Woods at 1.5 % and 35 % for each E, then big maps (E = 1).
    ``on_row(row)`` is called as each run finishes (a long benchmark shows its rows as they come)."""
    woods = load_map("35x36_Woods")
    jobs = [(woods, pct, e) for pct in (0.015, 0.35) for e in env_counts]
    if big:
        jobs += [(load_map("Borkenberge"), 0.015, 1), (tiled_map(), 0.015, 1)]
    runs = []
    for land, pct, e in jobs:
        r = time_fire(land, pct, e, steps, warmup)
        orig = ORIGINAL_STEPS_PER_S.get((r["map"], r["fire_percentage"]))
        r["original_steps_per_s"] = orig
        r["speedup_vs_original"] = r["env_steps_per_s"] / orig if orig else None
        runs.append(r)
        if on_row is not None:
            on_row(r)
    return {"arch": arch, "threads": threads or os.cpu_count(), "cpu_count": os.cpu_count(), "runs": runs}


def fire_footprint(land, fire_percentage: float, steps: int, layout: str = "auto", episodes: int = 3,
                   seed: int = 0) -> dict:
    """One env's memory (allocated, so also its peak), what the fire used of it over ``steps`` updates from a
    reset, and the time of the reset that ends such an episode (median over ``episodes``), in its two halves:
    clearing the last episode (the cost that follows the footprint in the sparse layout) and lighting the new
    initial fires (the same in either layout)."""
    cfg = IgnitionConfig(fire_percentage=fire_percentage, clusters=2)
    sim = FireSim(land, FireConfig(layout=layout), WindConfig(), cfg, num_envs=1, seed=seed)
    mask = np.ones(1, np.int32)

    def timed(kernel, *args) -> float:
        t0 = time.perf_counter()
        kernel(mask, *args)
        sim.counts.to_numpy()  # waits for the kernel
        return time.perf_counter() - t0

    sim.reset()
    sim.reset()  # compiles both halves
    chunk = max(1, steps // 10)
    peak_blocks = dropped_blocks = dropped_particles = lit = 0
    clear, start = [], []
    for _ in range(episodes):
        for _ in range(-(-steps // chunk)):
            sim.step(chunk)
        stats = sim.stats()  # the pool only grows within an episode: the last count is its peak
        peak_blocks = max(peak_blocks, int(stats["blocks"][0]))
        dropped_blocks += int(stats["dropped_blocks"][0])
        dropped_particles += int(stats["dropped_convection"][0] + stats["dropped_radiation"][0])
        lit = max(lit, int(stats["burning"][0] + stats["burned"][0]))
        clear.append(timed(sim._clear_envs))
        start.append(timed(sim._start_envs, sim.seed_key))
    return {"map": land.name, "cells": land.rows * land.cols, "fire_percentage": fire_percentage,
            "steps": chunk * -(-steps // chunk), "episodes": episodes, "layout": sim.layout,
            "block_capacity": sim.block_capacity, "blocks_total": sim.num_blocks, "peak_blocks": peak_blocks,
            "dropped_blocks": dropped_blocks, "dropped_particles": dropped_particles, "lit": lit,
            "memory_bytes_per_env": sim.memory_bytes_per_env(), "clear_s": float(np.median(clear)),
            "fires_s": float(np.median(start))}


FOOTPRINT_HEADER = (f"{'map':<16}{'cells':>9}{'ign':>7}{'layout':>8}{'MiB/env':>9}{'blocks used':>14}"
                    f"{'dropped':>9}{'clear ms':>10}{'fires ms':>10}")


def memory_report(steps: int, rss_envs: int, rss_steps: int, arch: str, threads: int | None, echo=print) -> dict:
    """``roshan bench memory``: the fire footprint per env and the reset cost of each layout on 35x36_Woods,
    Borkenberge and the 941k-cell tiled map (sparse and dense where ``auto`` would pick sparse for many envs), a
    line ``echo``-ed per run; with ``rss_envs``, the peak RSS of that many envs of the big map in a fresh
    process."""
    rows = []
    echo(FOOTPRINT_HEADER)
    for land in (load_map("35x36_Woods"), load_map("Borkenberge"), tiled_map()):
        for pct, n, episodes in ((0.015, steps, 3), (0.35, max(1, steps // 10), 1)):
            big = land.rows * land.cols > 100_000 and pct < 0.1  # where auto picks sparse for many envs
            for layout in ("sparse", "dense") if big else ("auto",):
                r = fire_footprint(land, pct, n, layout, episodes)
                rows.append(r)
                echo(format_footprint_row(r))
    report = {"arch": arch, "threads": threads, "runs": rows}
    if rss_envs:
        report["rss"] = rss = big_map_rss(rss_envs, rss_steps, arch, threads)
        echo(f"{rss_envs} envs of the 941k-cell map ({rss['layout']}), {rss_steps} updates: peak RSS "
             f"{rss['max_rss_bytes'] / 2**30:.2f} GiB ({rss['start_rss_bytes'] / 2**30:.2f} GiB before the "
             f"simulator, whose fields were estimated at {rss['estimate_bytes'] / 2**30:.2f} GiB), dropped "
             f"blocks {rss['dropped_blocks']}")
    return report


def format_footprint_row(r: dict) -> str:
    used = f"{r['peak_blocks']}/{r['block_capacity']}" if r["layout"] == "sparse" else "-"
    return (f"{r['map']:<16}{r['cells']:>9}{r['fire_percentage'] * 100:>6.1f}%{r['layout']:>8}"
            f"{r['memory_bytes_per_env'] / 2**20:>9.2f}{used:>14}{r['dropped_blocks'] + r['dropped_particles']:>9}"
            f"{r['clear_s'] * 1e3:>10.3f}{r['fires_s'] * 1e3:>10.2f}")


def _peak_rss_bytes() -> int:
    """This process's peak resident set (VmHWM). Not getrusage's ru_maxrss: Linux keeps that across the exec of
    a spawned child, so it would report the parent's RSS at the fork."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    raise RuntimeError("no VmHWM in /proc/self/status (Linux only)")


def _rss_child(queue, envs: int, steps: int, arch: str, threads: int | None) -> None:
    init_taichi(arch, threads)
    land = tiled_map()
    start = _peak_rss_bytes()  # Taichi's runtime and the map: what the memory estimate finds resident already
    sim = FireSim(land, ignition=IgnitionConfig(fire_percentage=0.015, clusters=2), num_envs=envs)
    sim.reset()
    sim.step(steps)
    stats = sim.stats()
    queue.put({"envs": envs, "steps": steps, "layout": sim.layout,
               "max_rss_bytes": _peak_rss_bytes(), "start_rss_bytes": start,
               "estimate_bytes": sim.sizes.estimate_bytes(sim.chunked is not None),
               "dropped_blocks": int(stats["dropped_blocks"].sum())})


def big_map_rss(envs: int = 64, steps: int = 500, arch: str = "cpu", threads: int | None = None) -> dict:
    """Peak RSS of a fresh process running ``envs`` envs of the 941k-cell map for ``steps`` updates."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    child = ctx.Process(target=_rss_child, args=(queue, envs, steps, arch, threads))
    child.start()
    out = queue.get()
    child.join()
    return out


FIRE_SPEED_HEADER = (f"{'map':<16}{'cells':>9}{'ign':>7}{'E':>6}{'env-steps/s':>14}{'burning upd/s':>15}"
                     f"{'x original':>12}{'KiB/env':>9}{'layout':>8}{'dropped':>9}")


def format_fire_row(r: dict) -> str:
    """One run of :func:`fire_speed` as a line under ``FIRE_SPEED_HEADER``."""
    sp = f"{r['speedup_vs_original']:.1f}" if r["speedup_vs_original"] else "-"
    return (f"{r['map']:<16}{r['cells']:>9}{r['fire_percentage'] * 100:>6.1f}%{r['envs']:>6}"
            f"{r['env_steps_per_s']:>14,.0f}{r['burning_cell_updates_per_s']:>15,.0f}{sp:>12}"
            f"{r['memory_bytes_per_env'] / 1024:>9.1f}{r.get('layout', 'dense'):>8}"
            f"{r['dropped'] + r.get('dropped_blocks', 0):>9}")


def format_fire_speed(report: dict) -> str:
    lines = [f"arch {report['arch']}, threads {report['threads']} (cpu_count {report['cpu_count']})",
             FIRE_SPEED_HEADER]
    base = {}
    for r in report["runs"]:
        key = (r["map"], r["fire_percentage"])
        if r["envs"] == 1:
            base[key] = r["env_steps_per_s"]
        lines.append(format_fire_row(r))
    for (m, p), one in base.items():
        scale = [r for r in report["runs"] if (r["map"], r["fire_percentage"]) == (m, p) and r["envs"] > 1]
        if scale:
            best = max(scale, key=lambda r: r["env_steps_per_s"])
            lines.append(f"scaling {m} {p * 100:g} %: best E={best['envs']} is {best['env_steps_per_s'] / one:.1f}x "
                         f"E=1" + "".join(f"; E={r['envs']}/E=1 {r['env_steps_per_s'] / one:.1f}x"
                                          for r in scale if r["envs"] == 256))
    return "\n".join(lines)


def plot_fidelity(results: dict, path: Path) -> Path:
    """One panel per (condition, quantity): reference mean and min..max band against our seed mean and range."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results)
    fig, axes = plt.subplots(len(names), len(REFERENCE_QUANTITIES), figsize=(16, 3.0 * len(names)), squeeze=False)
    for r, name in enumerate(names):
        rows = results[name]["rows"]
        t = np.array([row["step"] for row in rows]) * 0.1
        for c, q in enumerate(REFERENCE_QUANTITIES):
            ax = axes[r, c]
            v = {key: np.array([row[q][key] for row in rows]) for key in rows[0][q]}
            ax.fill_between(t, v["ref_min"], v["ref_max"], color="tab:orange", alpha=0.25, label="reference min..max")
            ax.plot(t, v["ref_mean"], color="tab:orange", label="reference mean")
            ax.fill_between(t, v["ours_min"], v["ours_max"], color="tab:blue", alpha=0.12, label="ours min..max")
            ax.plot(t, v["ours_mean"], color="tab:blue", label="ours mean")
            ax.set_title(f"{name}: {q}", fontsize=9)
            ax.tick_params(labelsize=7)
            if r == len(names) - 1:
                ax.set_xlabel("simulated time (s)", fontsize=8)
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------------- FlyAgent env

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
SHIPPED_COLLISION_MODEL = Path(__file__).resolve().parents[2] / "models" / "fly_collision"
ORIGINAL_FLY_EVAL_STEPS_PER_S = 935  # collision FlyAgent evaluation incl. policy inference, 35x36 at 1.5 %


def time_env(envs: int, drones: int, fire_percentage: float, steps: int, policy: str | None, collision: bool = True,
             seed: int = 0) -> dict:
    """Env-steps/s of the FlyAgent vector env (complex policy, collisions on), random actions or a network.

    ``policy``: None (random actions drawn in torch), "simple" or "collision" (an untrained FlyAgent actor
    sampling actions, inference only, with the frame cache the trainer uses), "fly_collision" (the shipped
    trained collision FlyAgent, deterministic actions: what the original's figure measures; its drones fly
    apart, so fewer neighbour slots are encoded, and reset less often), or "simple+ppo" / "collision+ppo" (the
    whole training iteration of configs/fly_simple.yaml / fly_collision.yaml at this E: rollouts of 16 steps and
    the PPO update). The first steps (kernel compilation) are not timed.
    """
    if policy is not None and policy.endswith("+ppo"):
        return time_training(envs, drones, fire_percentage, steps, policy.split("+")[0], seed)
    import torch

    cfg = Config(ignition=IgnitionConfig(fire_percentage=fire_percentage), drones=DroneConfig(num_drones=drones))
    env = FlyVectorEnv(envs, cfg, FlyConfig(policy="complex", collision=collision), seed=seed)
    obs, _ = env.reset(seed=seed)
    gen = torch.Generator().manual_seed(seed)
    if policy == "fly_collision":  # trained, deterministic: what evaluation runs
        fly = load_agent(SHIPPED_COLLISION_MODEL)[1].policy
        cache = fly.new_cache()
        network = lambda o: fly.act_deterministic(o, cache)  # noqa: E731
    elif policy is not None:  # untrained, sampling: what a rollout runs
        agent = fly_ppo(PPOConfig(use_tanh_dist=True), collision=policy == "collision")
        cache = agent.new_cache()
        network = lambda o: agent.sample(o, cache=cache).action  # noqa: E731

    @torch.no_grad()
    def act(o):
        if policy is None:
            return torch.rand((envs, drones, 2), generator=gen) * 2 - 1
        return network(flatten_drones(o)).view(envs, drones, 2)

    for _ in range(3):
        obs, *_ = env.step(act(obs))
    ended = 0
    t0 = time.perf_counter()
    for _ in range(steps):
        obs, _, term, trunc, _ = env.step(act(obs))
        done = term | trunc
        if policy is not None:
            cache.restart(done.repeat_interleave(drones))
        ended += int(done.sum())
    elapsed = time.perf_counter() - t0
    return {"envs": envs, "drones": drones, "fire_percentage": fire_percentage, "policy": policy or "random",
            "steps": steps, "seconds": elapsed, "env_steps_per_s": envs * steps / elapsed,
            "agent_steps_per_s": envs * drones * steps / elapsed, "episodes_ended": ended,
            "memory_bytes_per_env": env.fire.memory_bytes_per_env()}


def time_training(envs: int, drones: int, fire_percentage: float, steps: int, network: str, seed: int = 0) -> dict:
    """Env-steps/s of PPO training (rollout + update) with the config of the given network's setting."""
    import torch

    name = "fly_collision" if network == "collision" else "fly_simple"
    per_rollout = 16
    overrides = [f"sim.envs={envs}", f"drones.num_drones={drones}",
                 f"ignition.fire_percentage={fire_percentage}", f"ppo.horizon={envs * drones * per_rollout}"]
    cfg = load_run_config(CONFIGS / f"{name}.yaml", overrides)
    env = make_env(cfg, envs, seed)
    learner = PPOLearner(cfg, env, make_agent(cfg))
    gen = torch.Generator().manual_seed(seed)
    learner.iterate(gen)  # compiles
    iterations = max(1, steps // per_rollout)
    t0 = time.perf_counter()
    done = sum(learner.iterate(gen)[0] for _ in range(iterations))
    elapsed = time.perf_counter() - t0
    return {"envs": envs, "drones": drones, "fire_percentage": fire_percentage, "policy": f"{network}+ppo",
            "steps": done // envs, "seconds": elapsed, "env_steps_per_s": done / elapsed,
            "agent_steps_per_s": done * drones / elapsed, "episodes_ended": None,
            "memory_bytes_per_env": env.fire.memory_bytes_per_env()}


def env_speed(env_counts=(1, 64, 256, 1024, 4096), drones: int = 4, fire_percentages=(0.015, 0.35),
              policies=(None, "simple", "collision"), min_env_steps: int = 200_000, max_steps: int = 2000,
              on_row=None) -> dict:
    """The env benchmark: steps per run chosen so each run makes >= ``min_env_steps`` env-steps (capped).
    ``on_row(row)`` is called as each run finishes."""
    runs = []
    for pct in fire_percentages:
        for e in env_counts:
            steps = max(20, min(max_steps, min_env_steps // e))
            for pol in policies:
                steps_pol = steps if pol in (None, "simple") else max(16, steps // 4)  # the slow networks
                runs.append(time_env(e, drones, pct, steps_pol, pol))
                if on_row is not None:
                    on_row(runs[-1])
    return {"threads": os.cpu_count(), "runs": runs, "original_eval_env_steps_per_s": ORIGINAL_FLY_EVAL_STEPS_PER_S}


ENV_SPEED_HEADER = f"{'ign':>6}{'E':>6}{'policy':>15}{'env-steps/s':>14}{'agent-steps/s':>15}{'x original':>12}"


def format_env_row(r: dict) -> str:
    """One run of :func:`env_speed` as a line under ``ENV_SPEED_HEADER``."""
    return (f"{r['fire_percentage'] * 100:>5.1f}%{r['envs']:>6}{r['policy']:>15}"
            f"{r['env_steps_per_s']:>14,.0f}{r['agent_steps_per_s']:>15,.0f}"
            f"{r['env_steps_per_s'] / ORIGINAL_FLY_EVAL_STEPS_PER_S:>12.1f}")


def format_env_speed(report: dict) -> str:
    return "\n".join([ENV_SPEED_HEADER, *(format_env_row(r) for r in report["runs"])])
