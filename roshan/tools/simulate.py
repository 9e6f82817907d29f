"""``roshan simulate``: run the fire model on E envs, record a series, optionally dump frames and a GIF.

With ``drones=N`` the envs are FlyAgent envs (:class:`~roshan.env.fly.FlyVectorEnv`, complex policy: drones
extinguish the nearest unreserved fire) flown by a scripted policy of :mod:`roshan.env.heuristics`; one env
step is one fire update, and envs whose episode ends restart at once (same-step autoreset).
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from roshan.config import Config, ConfigError, FlyConfig, replace, to_dict
from roshan.io import prepare_output, write_atomic, write_gif, writing
from roshan.kernels.fire import FireSim
from roshan.kernels.fire_records import N_STEP
from roshan.maps import load_map
from roshan.runtime import init_taichi

SERIES_KEYS = ("burning", "burned", "convection", "radiation", "dropped_convection", "dropped_radiation")
# With drones, per env: episodes finished and successful so far, cells extinguished in the current episode and
# in all episodes so far, and the steps of the current episode.
DRONE_SERIES_KEYS = ("episodes", "successes", "extinguished", "extinguished_total", "episode_step")


@dataclass
class SimulationResult:
    """What a simulation produced: per-record stats, timing and the files written."""

    series: list[dict] = field(default_factory=list)
    timing: dict = field(default_factory=dict)
    frames: list[Path] = field(default_factory=list)
    gif: Path | None = None
    drones: dict | None = None  # drone runs: drones, policy, t_max, episodes, successes, success_rate, extinguished


def build_sim(cfg: Config) -> FireSim:
    """Initialise Taichi for ``cfg.sim`` and build the simulator on the configured map (not yet reset)."""
    init_taichi(cfg.sim.arch, cfg.sim.threads or None)
    land = load_map(cfg.map.name, band=cfg.map.band or None, rows=cfg.map.uniform_rows, cols=cfg.map.uniform_cols)
    return FireSim(land, cfg.fire, cfg.wind, cfg.ignition, num_envs=cfg.sim.envs, seed=cfg.sim.seed)


def record(sim: FireSim, counters: np.ndarray | None = None) -> dict:
    """One series record: the step and, per env, the counts of SERIES_KEYS (from ``counters``, as
    ``FireSim.step`` returns them, when given: no further read)."""
    c = sim.counters() if counters is None else counters
    stats = sim.stats(c)
    step = int(c[0, N_STEP])
    rec = {"step": step, "time_s": round(step * sim.dt, 6)}
    rec.update({k: stats[k].tolist() for k in SERIES_KEYS})
    return rec


def run_simulation(cfg: Config, steps: int, every: int = 100, frames_dir: Path | None = None,
                   gif: Path | None = None, progress: bool = True, drones: int | None = None,
                   policy: str = "greedy") -> SimulationResult:
    """Reset all envs, advance ``steps`` updates in chunks of ``every``, recording stats after each chunk.

    Frames (env 0) are written every ``every`` steps when ``frames_dir`` or ``gif`` is given. ``drones=N``
    flies N drones per env with ``policy`` (``"greedy"`` or ``"random"``, see :func:`run_drone_simulation`);
    ``None`` simulates the fire alone.
    """
    if drones is not None:
        return run_drone_simulation(cfg, steps, drones, policy, every, frames_dir, gif, progress)
    _check_steps(steps, every)
    sim = build_sim(cfg)
    renderer = scratch = None
    if frames_dir is not None or gif is not None:
        frames_dir, scratch = _frames_dir(frames_dir)
        from roshan.kernels.render import FrameRenderer  # frames only: it brings Pillow and GGUI

        renderer = FrameRenderer(sim)
    result = SimulationResult()
    t0 = time.perf_counter()
    sim.reset()
    result.series.append(record(sim))
    t_reset = time.perf_counter() - t0
    if renderer is not None:
        result.frames.append(renderer.save_png(frames_dir / _frame_name(0, 0.0)))
    sim_seconds = 0.0
    bar = _progress(steps, progress)
    done = 0
    while done < steps:
        n = min(every, steps - done)
        t1 = time.perf_counter()
        rec = record(sim, sim.step(n))  # the step returns the counters it read: the timing is honest
        sim_seconds += time.perf_counter() - t1
        done += n
        result.series.append(rec)
        if renderer is not None:
            result.frames.append(renderer.save_png(frames_dir / _frame_name(rec["step"], rec["time_s"])))
        if bar is not None:
            bar.update(n)
            # means per env, as in the summary (a sum over envs grows with --envs)
            bar.set_postfix({"burning/env": f"{np.mean(rec['burning']):.1f}",
                             "particles/env": f"{np.mean(rec['convection']) + np.mean(rec['radiation']):.0f}"})
    if bar is not None:
        bar.close()
    _finish_frames(renderer, result, gif, scratch, progress)
    result.timing = _timing(steps, cfg.sim.envs, t_reset, sim_seconds, sim.memory_bytes_per_env(), t0)
    return result


class _EpisodeTally:
    """Per-env running totals of finished episodes, successes and extinguished cells, kept as torch tensors so
    the step loop never waits on a host copy."""

    def __init__(self, env):
        import torch  # here, not at the top: fire-only runs never need torch

        self.env = env
        self.episodes, self.successes, self.extinguished = (
            torch.zeros(env.num_envs, dtype=torch.int64, device=env.device) for _ in range(3))

    def add(self, info: dict) -> None:
        # info's tensors are overwritten by the next step, so they are folded in right away.
        ended = info["_episode_stats"]
        ep = info["episode_stats"]
        self.episodes += ended
        self.successes += ended & (ep["success"] > 0.5)
        self.extinguished += ended * ep["extinguished"].round().long()

    def record(self, done: int) -> dict:
        """A series record after ``done`` steps: the fire's SERIES_KEYS plus DRONE_SERIES_KEYS, per env."""
        fire = self.env.fire
        stats = fire.stats()
        rec = {"step": done, "time_s": round(done * fire.dt, 6)}
        rec.update({k: stats[k].tolist() for k in SERIES_KEYS})
        current = stats["extinguished"]
        rec.update(episodes=self.episodes.tolist(), successes=self.successes.tolist(), extinguished=current.tolist(),
                   extinguished_total=(self.extinguished.cpu().numpy() + current).tolist(),
                   episode_step=fire.steps_since_reset().tolist())
        return rec


def run_drone_simulation(cfg: Config, steps: int, drones: int, policy: str = "greedy", every: int = 100,
                         frames_dir: Path | None = None, gif: Path | None = None,
                         progress: bool = True) -> SimulationResult:
    """``run_simulation`` with ``drones`` drones per env, each env a FlyVectorEnv episode (complex policy).

    ``policy``: ``"greedy"`` (the greedy baseline: the complex policy's nearest-unreserved-fire goals flown by
    :func:`~roshan.env.heuristics.straight_to_goal`) or ``"random"`` (uniform actions, seeded by
    ``cfg.sim.seed``). Records add, per env, :data:`DRONE_SERIES_KEYS`; ``step`` counts the run's steps
    (every env has made that many, across episodes). Frames show env 0 with its drones; its episode number
    is in the file name, since env 0 carries on into a new episode whenever one ends.
    """
    # Here, not at the top: the envs bring torch and gymnasium, which a fire-only run never needs.
    from roshan.env.heuristics import POLICIES

    _check_steps(steps, every)
    if isinstance(drones, bool) or not isinstance(drones, int | np.integer) or drones < 1:
        raise ValueError(f"--drones: expected a positive number of drones per env, got {drones!r} "
                         "(leave --drones out to simulate the fire alone)")
    if policy not in POLICIES:
        raise ValueError(f"--policy: expected one of {', '.join(POLICIES)}, got {policy!r}")
    try:
        cfg = replace(cfg, drones={**to_dict(cfg.drones), "num_drones": int(drones)})
    except ConfigError as exc:
        raise ConfigError(f"--drones: {exc}") from exc
    init_taichi(cfg.sim.arch, cfg.sim.threads or None)
    env, fly = _build_fly_env(cfg)
    renderer = overlay = scratch = None
    if frames_dir is not None or gif is not None:
        frames_dir, scratch = _frames_dir(frames_dir)
        from roshan.kernels.render import FrameRenderer, drone_overlay

        renderer, overlay = FrameRenderer(env.fire), drone_overlay(env.drones, 0)
    result = SimulationResult()
    tally = _EpisodeTally(env)
    t0 = time.perf_counter()
    obs, _ = env.reset()
    result.series.append(tally.record(0))
    t_reset = time.perf_counter() - t0

    def save_frame(rec: dict) -> None:
        if renderer is not None:
            name = _frame_name(rec["step"], rec["time_s"], episode=rec["episodes"][0])
            result.frames.append(renderer.save_png(frames_dir / name, overlay=overlay))

    save_frame(result.series[0])
    step_seconds = 0.0
    bar = _progress(steps, progress)
    generator = _generator(cfg.sim.seed, env.device)
    done = 0
    while done < steps:
        n = min(every, steps - done)
        t1 = time.perf_counter()
        obs = _fly(env, obs, n, policy, generator, tally)
        rec = tally.record(done + n)  # host copies wait for the kernels, so the timing is honest
        step_seconds += time.perf_counter() - t1
        done += n
        result.series.append(rec)
        save_frame(rec)
        if bar is not None:
            bar.update(n)
            bar.set_postfix({"burning/env": f"{np.mean(rec['burning']):.1f}", "episodes": int(np.sum(rec["episodes"]))})
    if bar is not None:
        bar.close()
    env.close()
    _finish_frames(renderer, result, gif, scratch, progress)
    result.timing = _timing(steps, cfg.sim.envs, t_reset, step_seconds, env.fire.memory_bytes_per_env(), t0)
    result.drones = _drone_summary(result.series[-1], int(drones), policy, fly, env.t_max)
    return result


def _build_fly_env(cfg: Config):
    from roshan.env.fly import FlyVectorEnv

    fly = FlyConfig(policy="complex")
    return FlyVectorEnv(num_envs=cfg.sim.envs, config=cfg, fly=fly, seed=cfg.sim.seed), fly


def _fly(env, obs: dict, n: int, policy: str, generator, tally: _EpisodeTally) -> dict:
    """Advance every env ``n`` steps under ``policy``, counting the episodes that end."""
    from roshan.env.heuristics import policy_actions

    for _ in range(n):
        obs, _, _, _, info = env.step(policy_actions(policy, env, obs, generator))
        tally.add(info)
    return obs


def _generator(seed: int, device):
    import torch

    return torch.Generator(device=device).manual_seed(int(seed))


def _drone_summary(last: dict, drones: int, policy: str, fly, t_max: int) -> dict:
    episodes, successes = int(np.sum(last["episodes"])), int(np.sum(last["successes"]))
    return {"drones": drones, "policy": policy, "fly_policy": fly.policy, "t_max": t_max, "episodes": episodes,
            "successes": successes, "success_rate": successes / episodes if episodes else None,
            "extinguished": int(np.sum(last["extinguished_total"]))}


def _check_steps(steps: int, every: int) -> None:
    if steps < 0 or every < 1:
        raise ValueError(f"steps must be >= 0 and every >= 1 (got steps={steps}, every={every})")


def prepare_outputs(frames_dir: Path | None, gif: Path | None, json_path: Path | None) -> None:
    """Create the output folders and check they can be written before anything is simulated: a run of hours
    must not end by losing its results to a missing or read-only folder."""
    if frames_dir is not None:
        prepare_output(frames_dir, "frames")
    if gif is not None:
        prepare_output(gif, "the GIF", is_dir=False)
    if json_path is not None:
        prepare_output(json_path, "the JSON series", is_dir=False)


def _frames_dir(frames_dir: Path | None) -> tuple[Path, Path | None]:
    """(the folder frames go to, the scratch folder to remove afterwards): ``--frames DIR``, or for a GIF alone
    a temporary folder, so that ``--gif`` leaves nothing but the GIF behind."""
    if frames_dir is not None:
        return prepare_output(frames_dir, "frames"), None
    scratch = Path(tempfile.mkdtemp(prefix="roshan_frames_"))
    return scratch, scratch


def _finish_frames(renderer, result: SimulationResult, gif: Path | None, scratch: Path | None = None,
                   progress: bool = False) -> None:
    if renderer is not None:
        renderer.close()
        try:
            if gif is not None:
                if progress:
                    from tqdm import tqdm

                    tqdm.write(f"writing the GIF {gif} ({len(result.frames)} frames)")
                with writing("the GIF", gif):
                    result.gif = write_gif(result.frames, Path(gif))
        finally:
            if scratch is not None:
                shutil.rmtree(scratch, ignore_errors=True)


def _timing(steps: int, envs: int, t_reset: float, step_seconds: float, memory: int, t0: float) -> dict:
    env_steps = steps * envs
    return {
        "steps": steps,
        "envs": envs,
        "reset_s": t_reset,
        "step_s": step_seconds,
        "env_steps_per_s": env_steps / step_seconds if step_seconds > 0 else float("nan"),
        "memory_bytes_per_env": memory,
        "wall_s": time.perf_counter() - t0,
    }


def write_json(cfg: Config, result: SimulationResult, path: Path) -> None:
    """``{"config": ..., "series": [...], "timing": {...}}`` (plus ``"drones": {...}`` for drone runs); all but
    ``timing`` is a function of the seed. For drone runs ``config.drones.num_drones`` is the run's N."""
    data = {"config": to_dict(cfg), "series": result.series, "timing": result.timing}
    if result.drones is not None:
        data["config"]["drones"]["num_drones"] = result.drones["drones"]
        data["drones"] = result.drones
    with writing("the JSON series", path):
        write_atomic(path, json.dumps(data, indent=1).encode())


def summary_lines(result: SimulationResult) -> list[str]:
    """Human summary of the last record and the speed."""
    last = result.series[-1]
    t = result.timing
    lines = [
        f"simulated {t['steps']} steps x {t['envs']} envs ({last['time_s']:.1f} s of fire) "
        f"in {t['step_s']:.2f} s: {t['env_steps_per_s']:,.0f} env-steps/s",
        f"env 0: burning {last['burning'][0]}, burned {last['burned'][0]}, "
        f"particles {last['convection'][0]} convection / {last['radiation'][0]} radiation",
    ]
    if t["envs"] > 1:
        lines.append(f"all envs: burning {int(np.mean(last['burning']))} (mean), burned "
                     f"{int(np.mean(last['burned']))} (mean)")
    dropped = int(np.sum(last["dropped_convection"]) + np.sum(last["dropped_radiation"]))
    if dropped:
        lines.append(f"WARNING: {dropped} particles dropped (pool full); raise fire.conv_capacity / rad_capacity")
    dropped_blocks = int(np.sum(last.get("dropped_blocks", 0)))
    if dropped_blocks:
        lines.append(f"WARNING: {dropped_blocks} cell writes found the sparse block pool full (the fire outgrew it); "
                     "raise fire.block_capacity or set fire.layout: dense")
    if result.drones is not None:
        lines.extend(_drone_lines(result.drones))
    lines.append(f"memory per env: {t['memory_bytes_per_env'] / 1024:.1f} KiB")
    if result.gif is not None:
        lines.append(f"gif: {result.gif}")
    elif result.frames:
        lines.append(f"frames: {len(result.frames)} PNGs in {result.frames[0].parent}")
    return lines


def _drone_lines(d: dict) -> list[str]:
    rate = "n/a" if d["success_rate"] is None else f"{100 * d['success_rate']:.1f} %"
    lines = [f"drones: {d['drones']} per env, policy {d['policy']} ({d['fly_policy']} goals); episodes finished "
             f"{d['episodes']} (all envs), success rate {rate} ({d['successes']}/{d['episodes']}); "
             f"cells extinguished {d['extinguished']}"]
    if d["episodes"] == 0:
        lines.append(f"no episode ended yet: an episode lasts at most {d['t_max']} steps (or until every fire is out)")
    return lines


def _frame_name(step: int, time_s: float, episode: int | None = None) -> str:
    # Drone runs: env 0 restarts whenever its episode ends, so the name says which episode the frame shows.
    suffix = "" if episode is None else f"_ep{episode:04d}"
    return f"frame_{step:07d}_t{time_s:08.1f}s{suffix}.png"


def _progress(total: int, enabled: bool):
    if not enabled or total <= 0:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="step", desc="simulate", dynamic_ncols=True)
