"""``roshan simulate``: run the fire model on E envs, record a series, optionally dump frames and a GIF; the
series, frame, timing and output helpers that :mod:`roshan.tools.simulate_drones` (``--drones N``) shares.

A fire-only run imports neither the envs nor torch and gymnasium: they cost a second of start-up (issue 34).
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from roshan.config import Config, to_dict
from roshan.io import OutputError, prepare_output, refuse_overwrite, write_atomic, write_gif, writing
from roshan.io import progress_bar as io_progress_bar
from roshan.kernels.annotate import annotate
from roshan.kernels.fire import FireSim
from roshan.kernels.fire_records import N_STEP
from roshan.kernels.render import BURNED_LABEL, FrameRenderer, frame_legend
from roshan.maps import class_histogram, load_map
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
                   gif: Path | None = None, progress: bool = True) -> SimulationResult:
    """Reset all envs, advance ``steps`` updates in chunks of ``every``, recording stats after each chunk.

    Frames (env 0) are written every ``every`` steps when ``frames_dir`` or ``gif`` is given. The fire alone:
    :func:`roshan.tools.simulate_drones.run_drone_simulation` flies drones too.
    """
    check_steps(steps, every)
    sim = build_sim(cfg)
    renderer = scratch = None
    if frames_dir is not None or gif is not None:
        frames_dir, scratch = frames_dir_or_scratch(frames_dir)
        renderer = FrameRenderer(sim)
    result = SimulationResult()
    t0 = time.perf_counter()
    sim.reset()
    result.series.append(record(sim, sim.step(0)))  # step(0) builds the update kernel here, not in the timed loop
    t_reset = time.perf_counter() - t0
    legend = frame_legend(classes=tuple(class_histogram(sim.land_map))) if renderer is not None else []
    if renderer is not None:
        rec = result.series[0]
        result.frames.append(save_frame(renderer.render(), frames_dir / frame_name(0, 0.0), fire_caption(rec), legend))
    sim_seconds = 0.0
    bar = progress_bar(steps, progress)
    done = 0
    while done < steps:
        n = min(every, steps - done)
        t1 = time.perf_counter()
        rec = record(sim, sim.step(n))  # the step returns the counters it read: the timing is honest
        sim_seconds += time.perf_counter() - t1
        done += n
        result.series.append(rec)
        if renderer is not None:
            result.frames.append(save_frame(renderer.render(), frames_dir / frame_name(rec["step"], rec["time_s"]),
                                            fire_caption(rec), legend))
        if bar is not None:
            bar.update(n)
            # means per env, as in the summary (a sum over envs grows with --envs)
            bar.set_postfix({"burning/env": f"{np.mean(rec['burning']):.1f}",
                             "particles/env": f"{np.mean(rec['convection']) + np.mean(rec['radiation']):.0f}"})
    if bar is not None:
        bar.close()
    if renderer is not None:
        renderer.close()
    finish_frames(renderer is not None, result, gif, scratch, progress)
    result.timing = timing(steps, cfg.sim.envs, t_reset, sim_seconds, sim.memory_bytes_per_env(), t0)
    return result


def fire_caption(rec: dict) -> str:
    """The caption of a fire-only frame (env 0 of series record ``rec``), in the parts of the envs' captions."""
    return (f"fire alone | step {rec['step']} | t = {rec['time_s']:.1f} s | burning {rec['burning'][0]} | "
            f"{BURNED_LABEL} {rec['burned'][0]}")


def save_frame(frame: np.ndarray, path: Path, caption: str, legend: list) -> Path:
    """``frame`` with its caption band above and legend band below (as the envs' frames), as a PNG at ``path``."""
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(annotate(frame, caption, legend)).save(path)
    return path


def check_steps(steps: int, every: int) -> None:
    if steps < 0 or every < 1:
        raise ValueError(f"steps must be >= 0 and every >= 1 (got steps={steps}, every={every})")


def prepare_outputs(frames_dir: Path | None, gif: Path | None, json_path: Path | None, replace: bool = False) -> None:
    """Create the output folders and check they can be written before anything is simulated: a run of hours
    must not end by losing its results to a missing or read-only folder. An existing GIF or JSON file is refused
    unless ``replace`` (before anything is created), as is a --frames folder that already holds frames."""
    refuse_overwrite(gif, "the GIF", replace)
    refuse_overwrite(json_path, "the JSON series", replace)
    if frames_dir is not None and not replace and any(Path(frames_dir).glob("frame_*.png")):
        raise OutputError("frames", frames_dir, "the folder holds frames already; give --replace to overwrite them, "
                                                "or name a new folder")
    if frames_dir is not None and replace:  # the old run's frames go: a folder holds one run's frames
        with writing("frames", frames_dir):
            for old in Path(frames_dir).glob("frame_*.png"):
                old.unlink()
    if frames_dir is not None:
        prepare_output(frames_dir, "frames")
    if gif is not None:
        prepare_output(gif, "the GIF", is_dir=False)
    if json_path is not None:
        prepare_output(json_path, "the JSON series", is_dir=False)


def frames_dir_or_scratch(frames_dir: Path | None) -> tuple[Path, Path | None]:
    """(the folder frames go to, the scratch folder to remove afterwards): ``--frames DIR``, or for a GIF alone
    a temporary folder, so that ``--gif`` leaves nothing but the GIF behind."""
    if frames_dir is not None:
        return prepare_output(frames_dir, "frames"), None
    scratch = Path(tempfile.mkdtemp(prefix="roshan_frames_"))
    return scratch, scratch


def finish_frames(rendered: bool, result: SimulationResult, gif: Path | None, scratch: Path | None = None,
                   progress: bool = False) -> None:
    """Where frames were ``rendered``: stitch them into ``gif`` (when given) and remove the ``scratch`` folder."""
    if rendered:
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


def timing(steps: int, envs: int, t_reset: float, step_seconds: float, memory: int, t0: float) -> dict:
    env_steps = steps * envs
    wall = time.perf_counter() - t0
    return {
        "steps": steps,
        "envs": envs,
        "reset_s": t_reset,
        "step_s": step_seconds,
        "env_steps_per_s": env_steps / step_seconds if step_seconds > 0 else float("nan"),
        "memory_bytes_per_env": memory,
        "wall_s": wall,
        "wall_env_steps_per_s": env_steps / wall if wall > 0 else float("nan"),
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
        f"in {t['wall_s']:.2f} s: {t['wall_env_steps_per_s']:,.0f} env-steps/s (the updates alone: "
        f"{t['step_s']:.2f} s, {t['env_steps_per_s']:,.0f} env-steps/s; the rest is the reset, building kernels, "
        f"records and frames)",
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


def frame_name(step: int, time_s: float, episode: int | None = None) -> str:
    # Drone runs: env 0 restarts whenever its episode ends, so the name says which episode the frame shows (1 for
    # the first, as in the frame's caption).
    suffix = "" if episode is None else f"_ep{episode:04d}"
    return f"frame_{step:07d}_t{time_s:08.1f}s{suffix}.png"


def progress_bar(total: int, enabled: bool):
    if not enabled or total <= 0:
        return None
    return io_progress_bar(total=total, unit="step", desc="simulate", dynamic_ncols=True)
