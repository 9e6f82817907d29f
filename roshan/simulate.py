"""``roshan simulate``: run the fire model on E envs, record a series, optionally dump frames and a GIF."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from roshan.config import Config, to_dict
from roshan.kernels.fire import FireSim
from roshan.maps import load_map
from roshan.runtime import init_taichi

SERIES_KEYS = ("burning", "burned", "convection", "radiation", "dropped_convection", "dropped_radiation")


@dataclass
class SimulationResult:
    """What a simulation produced: per-record stats, timing and the files written."""

    series: list[dict] = field(default_factory=list)
    timing: dict = field(default_factory=dict)
    frames: list[Path] = field(default_factory=list)
    gif: Path | None = None


def build_sim(cfg: Config) -> FireSim:
    """Initialise Taichi for ``cfg.sim`` and build the simulator on the configured map (not yet reset)."""
    init_taichi(cfg.sim.arch, cfg.sim.threads or None)
    land = load_map(cfg.map.name, band=cfg.map.band or None, rows=cfg.map.uniform_rows, cols=cfg.map.uniform_cols)
    return FireSim(land, cfg.fire, cfg.wind, cfg.ignition, num_envs=cfg.sim.envs, seed=cfg.sim.seed)


def record(sim: FireSim) -> dict:
    """One series record: the step and, per env, the counts of SERIES_KEYS."""
    stats = sim.stats()
    step = int(sim.steps_since_reset()[0])
    rec = {"step": step, "time_s": round(step * sim.dt, 6)}
    rec.update({k: stats[k].tolist() for k in SERIES_KEYS})
    return rec


def run_simulation(cfg: Config, steps: int, every: int = 100, frames_dir: Path | None = None,
                   gif: Path | None = None, progress: bool = True) -> SimulationResult:
    """Reset all envs, advance ``steps`` updates in chunks of ``every``, recording stats after each chunk.

    Frames (env 0) are written every ``every`` steps when ``frames_dir`` or ``gif`` is given.
    """
    if steps < 0 or every < 1:
        raise ValueError(f"steps must be >= 0 and every >= 1 (got steps={steps}, every={every})")
    sim = build_sim(cfg)
    renderer = None
    if frames_dir is not None or gif is not None:
        from roshan.kernels.render import FrameRenderer

        frames_dir = Path(frames_dir) if frames_dir is not None else Path(gif).with_suffix("").parent / "frames"
        frames_dir.mkdir(parents=True, exist_ok=True)
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
        sim.step(n)
        rec = record(sim)  # the host copy also waits for the kernel, so the timing is honest
        sim_seconds += time.perf_counter() - t1
        done += n
        result.series.append(rec)
        if renderer is not None:
            result.frames.append(renderer.save_png(frames_dir / _frame_name(rec["step"], rec["time_s"])))
        if bar is not None:
            bar.update(n)
            bar.set_postfix(burning=int(np.sum(rec["burning"])), particles=int(np.sum(rec["convection"])
                                                                                + np.sum(rec["radiation"])))
    if bar is not None:
        bar.close()
    if renderer is not None:
        renderer.close()
        if gif is not None:
            from roshan.kernels.render import write_gif

            result.gif = write_gif(result.frames, Path(gif))
    env_steps = steps * cfg.sim.envs
    result.timing = {
        "steps": steps,
        "envs": cfg.sim.envs,
        "reset_s": t_reset,
        "step_s": sim_seconds,
        "env_steps_per_s": env_steps / sim_seconds if sim_seconds > 0 else float("nan"),
        "memory_bytes_per_env": sim.memory_bytes_per_env(),
        "wall_s": time.perf_counter() - t0,
    }
    return result


def write_json(cfg: Config, result: SimulationResult, path: Path) -> None:
    """``{"config": ..., "series": [...], "timing": {...}}``; all but ``timing`` is a function of the seed."""
    Path(path).write_text(json.dumps({"config": to_dict(cfg), "series": result.series, "timing": result.timing},
                                     indent=1))


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
    lines.append(f"memory per env: {t['memory_bytes_per_env'] / 1024:.1f} KiB")
    if result.gif is not None:
        lines.append(f"gif: {result.gif}")
    elif result.frames:
        lines.append(f"frames: {len(result.frames)} PNGs in {result.frames[0].parent}")
    return lines


def _frame_name(step: int, time_s: float) -> str:
    return f"frame_{step:07d}_t{time_s:08.1f}s.png"


def _progress(total: int, enabled: bool):
    if not enabled or total <= 0:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="step", desc="simulate", dynamic_ncols=True)
