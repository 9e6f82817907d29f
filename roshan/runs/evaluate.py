"""Evaluation: deterministic episodes of a trained FlyAgent -> success, failure reasons, TTE; CSV, JSON, plots.

Episodes are spread over E envs; each env runs ``ceil(n / E)`` whole episodes and the first n of them (in env
order) are kept, so short episodes are not over-represented the way "stop at the n-th finished episode" would.
The env seed makes an evaluation repeatable: the same seed gives the same fire layouts and wind.
"""

import json
import math
import shlex
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from roshan.algos.buffers import ReplayBuffer
from roshan.algos.frozen import load_for_acting, policy_fn
from roshan.algos.networks import flatten_drones
from roshan.checkpoints import folder_lock, resolve_checkpoint
from roshan.config import Config, Level, check_model_level
from roshan.env.fly import FlyVectorEnv
from roshan.episode import EXTRA_COLUMNS, REASONS, RECORD_FIELDS, RECORD_INFO
from roshan.io import OutputError, prepare_output, refuse_overwrite, write_gif, writing
from roshan.io import progress_bar as new_bar
from roshan.runs.baselines import BASELINES
from roshan.runs.collect import next_observation
from roshan.runs.envs import caption_name, make_env
from roshan.runs.levels import kit_of
from roshan.runs.provenance import code_version, settings_hash
from roshan.runs.report.files import write_episodes_csv, write_summary_json
from roshan.runs.report.notes import controller_notes, setting_notes
from roshan.runs.report.plots import plot_comparison, plot_episodes, plot_learning_curves
from roshan.runs.report.scalars import read_tensorboard_scalars
from roshan.runs.report.stats import summarize
from roshan.runs.report.tables import format_table
from roshan.runtime import current_arch, ensure_taichi, torch_device, use_acting_threads


@torch.no_grad()
def run_episodes(env: FlyVectorEnv, act, episodes: int, seed: int, frames_dir: Path | None = None,
                 progress_bar: bool = False, on_step=None) -> dict[str, np.ndarray]:
    """Run ``episodes`` whole episodes with ``act(obs_batch) -> actions`` and return their records.

    Returns a dict of arrays: reward (absent where the env's controller earns none, ``env.has_reward``), time
    (steps), success, reason (str), the fire at the end: burned (burned out), burning and lit (ever lit) as
    fractions of the map's cells and extinguished (cells); env, index; and the record's extra columns the env's
    drones count (``env.extra_columns``: counts as ints).
    ``on_step(obs, actions, rewards, terms, truncs, info)`` is called after every step (buffer recording).
    With ``frames_dir`` the frames of env 0's first episode are written there: frame 0 is the state right after
    the reset and the last frame the episode's final state (which an env built with ``render_mode="rgb_array"``
    renders before the same-step autoreset).

    The progress bar counts episodes, and on a terminal moves with the steps too: each env's running episode adds
    the fraction of its step limit it has used (capped below one), so a batch of long episodes does not sit at 0.
    Without a terminal it counts finished episodes only, in whole numbers.
    """
    E, N = env.num_envs, env.num_drones
    quota = math.ceil(episodes / E)
    obs, _ = env.reset(seed=seed)
    done_count = torch.zeros(E, dtype=torch.long)
    rows: list[list] = [[] for _ in range(E)]
    frame = 0
    if frames_dir is not None:
        if env.render_mode is None:
            raise ValueError(f"frames_dir={str(frames_dir)!r}: this env was built without render_mode='rgb_array', "
                             "so it keeps no episode's final frame; build it with render_mode='rgb_array'")
        _save_frame(env.render(), frames_dir, frame)
        frame += 1
    # On a terminal the bar moves with the running episodes too (4.7/8); without one (a log file, CI) every line it
    # prints stays, so it counts finished episodes only, in whole numbers.
    fractional = progress_bar and sys.stderr.isatty()
    bar = new_bar(total=quota * E, unit="episode", disable=not progress_bar, desc="eval",
               bar_format="{l_bar}{bar}| {n:" + (".1f" if fractional else ".0f") + "}/{total_fmt} episodes "
                          "[{elapsed}<{remaining}]")
    steps = torch.zeros(E, dtype=torch.long)  # steps of each env's running episode, for the bar
    t_max = env.max_env_steps
    flat = env.flat_drones  # FlyAgent policies see drones as a batch
    while int(done_count.min()) < quota:
        actions = act(flatten_drones(obs)).view(E, N, 2) if flat else act(obs)
        obs, rewards, terms, truncs, info = env.step(actions)
        if on_step is not None:
            on_step(obs, actions, rewards, terms, truncs, info)
        ended = info["_episode_stats"]
        if frames_dir is not None and int(done_count[0]) == 0:
            env_zero_ended = bool(ended[0])
            _save_frame(env.final_frame if env_zero_ended else env.render(), frames_dir, frame)
            frame += 1
        if bool(ended.any()):
            stats = torch.stack([info[key][k] for key, fields in RECORD_INFO.items() for k in fields],
                                dim=-1).cpu().numpy()  # (E, RECORD_FIELDS)
            for e in ended.nonzero().flatten().tolist():
                if done_count[e] < quota:
                    rows[e].append(stats[e])
                    done_count[e] += 1
        if progress_bar:
            steps += 1
            steps[ended.cpu()] = 0
            _advance_bar(bar, done_count, steps if fractional else torch.zeros_like(steps), quota, t_max)
    bar.close()
    kept = [(e, i, r) for e in range(E) for i, r in enumerate(rows[e])][:episodes]
    col = lambda name: np.array([r[RECORD_FIELDS.index(name)] for _, _, r in kept])  # noqa: E731
    out = {"reward": col("return"), "time": col("steps").astype(int), "success": col("success").astype(int),
           "reason": np.array([REASONS[int(v)] for v in col("reason")]), "burned": col("burned_fraction"),
           "burning": col("burning_fraction"), "lit": col("lit_fraction"),
           "extinguished": col("extinguished").astype(int), "env": np.array([e for e, _, _ in kept]),
           "index": np.array([i for _, i, _ in kept])}
    for c in env.extra_columns:  # the extra columns the drones counted, per episode
        out[c.name] = col(c.name).astype(int) if c.is_count else col(c.name)
    if not env.has_reward:
        del out["reward"]
    return out


def _advance_bar(bar, done_count: torch.Tensor, steps: torch.Tensor, quota: int, t_max: int) -> None:
    """Finished episodes plus each unfinished env's share of its running one (steps / step limit, below 1)."""
    running = torch.where(done_count < quota, (steps.float() / t_max).clamp(max=0.99), torch.zeros(()))
    n = float(done_count.clamp(max=quota).sum()) + float(running.sum())
    bar.update(n - bar.n)


def _save_frame(picture: np.ndarray, frames_dir: Path, k: int) -> None:
    from PIL import Image

    frames_dir.mkdir(parents=True, exist_ok=True)
    Image.fromarray(picture).save(frames_dir / f"frame_{k:05d}.png")


# Under a FlyAgent of the simple policy (fly.policy: simple) a drone's task is to reach its goal, not to put out fire.
SIMPLE_POLICY_NOTE = ("fly.policy = simple: an episode succeeds when the drones reach their goals; they put out no "
                      "fire, so Extinguished reads 0")
def training_note(level: Level, scalars: dict) -> str | None:
    """The learning curves' note for ``level`` (where its training and evaluation differ by design,
    ``Level.training_note``) plus the training episodes' success rate at the first and the last point of the run's
    log (``Episodes/success_rate``), so the note never contradicts the curve under it."""
    note = level.training_note or None
    points = scalars.get("Episodes/success_rate")
    if note is None or not points:
        return note
    first, last = points[0][1], points[-1][1]
    return f"{note} Training success {first:.2f} at the first point, {last:.2f} at the last."


def _say(line: str) -> None:
    """A line about a slow phase, printed above any progress bar."""
    tqdm.write(line)


def _quiet(line: str) -> None:
    pass


# The files that make an evaluation; a folder holding one of them holds results (the plots are rewritten by name).
RESULT_FILES = ("episodes.csv", "summary.json", "table.txt")


def held_results(folder: Path) -> list[str]:
    """The result files already in ``folder`` (and in its baseline subfolders), relative to it."""
    return [str(p.relative_to(folder)) for sub in ("", *BASELINES) for name in RESULT_FILES
            if (p := Path(folder) / sub / name).is_file()]


def _clear_results(folder: Path) -> None:
    """Remove an earlier evaluation's files that a new one may not rewrite (a baseline's folder, comparisons)."""
    for sub in ("", *BASELINES):
        for name in RESULT_FILES:
            (Path(folder) / sub / name).unlink(missing_ok=True)
    for p in Path(folder).glob("comparison_*.png"):
        p.unlink()


def _refuse_existing(what: str, path: Path, held: str, way_out: str) -> None:
    raise OutputError(what, path, f"it already holds {held}; give --replace to overwrite it, or {way_out}")


def output_lock(out_dir: Path):
    """Hold ``out_dir/.lock`` while an evaluation writes there: a second evaluation into the same folder is refused
    (:class:`OutputError` naming who holds it) before it clears or writes anything, instead of both writing and the
    folder keeping one of them. Creates ``out_dir`` if needed."""
    prepare_output(out_dir, "evaluation files")
    return folder_lock(out_dir / ".lock", lambda holder: OutputError(
        "evaluation files", out_dir, f"another evaluation is writing there ({holder}); wait for it, or give --out "
                                     "DIR to write a new folder"))


def _refuse_held(out_dir: Path, json_path: Path | None, frames_dir: Path | None, gif_path: Path | None) -> None:
    """Without --replace: refuse a folder that holds an evaluation, an existing JSON or GIF file or a frames folder
    with frames (:class:`OutputError` naming it and the two ways out)."""
    if held := held_results(out_dir):
        _refuse_existing("evaluation files", out_dir, f"an evaluation ({', '.join(held)})",
                         "--out DIR to write a new folder")
    for what, path, flag in (("the evaluation JSON", json_path, "--json"), ("the GIF", gif_path, "--gif")):
        if path is not None and Path(path).is_file():
            _refuse_existing(what, path, "a file of that name", f"{flag} FILE naming a new file")
    if frames_dir is not None and any(Path(frames_dir).glob("frame_*.png")):
        _refuse_existing("frames", frames_dir, "frames", "--frames DIR naming a new folder")


def prepare_outputs(out_dir: Path, json_path: Path | None, frames_dir: Path | None, gif_path: Path | None,
                    replace: bool = False) -> None:
    """Create the evaluation's output folders and check they can be written before any episode runs. Without
    ``replace``, a folder that holds an evaluation, an existing JSON or GIF file or a frames folder with frames
    is refused (:class:`OutputError` naming it and the two ways out); with it, the old evaluation's files go.
    Call it holding :func:`output_lock`, so that what it clears is no other evaluation's."""
    if not replace:
        _refuse_held(out_dir, json_path, frames_dir, gif_path)
    prepare_output(out_dir, "evaluation files")
    if replace:
        with writing("evaluation files", out_dir):
            _clear_results(out_dir)
    if json_path is not None:
        prepare_output(json_path, "the evaluation JSON", is_dir=False)
    if frames_dir is not None:
        prepare_output(frames_dir, "frames")
    if gif_path is not None:
        prepare_output(gif_path, "the GIF", is_dir=False)


# The models shipped with the checkout: their folders are tracked files, so evaluations of them go under out/
# (gitignored) instead, and a checkout stays clean after the README's commands.
SHIPPED_MODELS = Path(__file__).resolve().parents[2] / "models"


def eval_root(run_dir: Path) -> Path:
    """Where ``roshan eval RUN``'s folders go by default: ``RUN/eval``, or for a model shipped in the checkout's
    ``models/`` ``out/eval/<model>`` (relative to the working directory)."""
    run_dir = Path(run_dir)
    if run_dir.resolve().parent == SHIPPED_MODELS.resolve():
        return Path("out") / "eval" / run_dir.name
    return run_dir / "eval"


def evaluation_name(seed: int, episodes: int, settings: dict) -> str:
    """An evaluation's folder name: ``<seed>-<episodes>``, plus ``-<hash>`` of ``settings`` (whatever else
    changes the results: overrides, baseline, checkpoint, envs, arch) when there are any."""
    return f"{seed}-{episodes}" + (f"-{settings_hash(settings)}" if settings else "")


def default_checkpoint(run_dir: Path) -> Path | None:
    """The checkpoint `roshan eval RUN` takes without --checkpoint (None for a checkpoint file outside a run)."""
    try:
        return resolve_checkpoint(run_dir, "best")
    except FileNotFoundError:
        return None


def _provenance(target, path: Path, which: str, seed: int, episodes: int, num_envs: int, overrides, baseline,
                arch: str) -> dict:
    """What a summary JSON records about how it was made: the command that reproduces it (and the process's own
    command line), the overrides, the checkpoint, the code version."""
    command = ["roshan", "eval", str(target), "--episodes", str(episodes), "--seed", str(seed), "--envs",
               str(num_envs), "--checkpoint", which, *(["--baseline", baseline] if baseline else []),
               *[a for o in overrides for a in ("--set", o)], *(["--arch", arch] if arch != "cpu" else [])]
    return {"command": shlex.join(command), "argv": shlex.join(sys.argv), "target": str(target),
            "overrides": list(overrides), "checkpoint": str(path), "checkpoint_choice": which, "seed": seed,
            "episodes": episodes, "envs": num_envs, "baseline": baseline, "arch": arch, "code": code_version()}


def write_outputs(episodes: dict, out_dir: Path, title: str, provenance: dict | None = None,
                  reasons: tuple[str, ...] = ("collision", "boundary", "timeout"), dt: float | None = None,
                  who: str | None = None, say=_quiet, notes: Sequence[str] = ()) -> dict:
    """episodes.csv, summary.json (with ``provenance``) and the plots in ``out_dir``; returns the summary.
    ``reasons`` are the failures the controller's records can hold (``env.failure_reasons``), ``dt`` the seconds
    per step (TTE in seconds), ``who`` the controller named in the plot titles; ``say(line)`` announces the slow
    part (the plots). A result that cannot mean what its rates suggest gets ``summary["notes"]``
    (:func:`controller_notes`, plus the setting's ``notes``), printed under its table."""
    with writing("evaluation files", out_dir):
        return _write_outputs(episodes, out_dir, title, provenance, reasons, dt, who, say, notes)


def _write_outputs(episodes: dict, out_dir: Path, title: str, provenance, reasons, dt, who, say, notes) -> dict:
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = summarize(episodes, reasons=reasons, dt=dt)
    found = [*notes, *controller_notes(summary, who or "the controller")]
    if found:  # only where there is something to say: summaries of meaningful results stay as they were
        summary["notes"] = found
    if provenance is not None:
        summary["provenance"] = provenance
    write_episodes_csv(episodes, out_dir / "episodes.csv")
    write_summary_json(summary, out_dir / "summary.json")
    say(f"writing plots of {who or 'the evaluation'} to {out_dir}")
    plot_episodes(episodes, out_dir, reasons=reasons, who=who)
    (out_dir / "table.txt").write_text(format_table(summary, title) + "\n")
    return summary


def _note_simple_policy(cfg: Config, summary: dict, out: Path) -> None:
    """Under a simple-policy FlyAgent a table of 100 % success beside 0 extinguished says why: in ``summary["note"]``
    (printed under the table) and at the end of ``table.txt``."""
    if not cfg.train.level.fights_fire(cfg):
        summary["note"] = SIMPLE_POLICY_NOTE
        with (out / "table.txt").open("a") as table:
            table.write(SIMPLE_POLICY_NOTE + "\n")


def write_learning_curves(run_dir: Path, path: Path, title: str, level: Level, say=_quiet) -> None:
    """The run's learning curves from its TensorBoard events (nothing where it has none), with the note of
    :func:`training_note` where training and evaluation differ by design."""
    tb = run_dir / "tb"
    scalars = read_tensorboard_scalars(tb) if tb.is_dir() else {}
    if scalars:
        say(f"writing learning curves to {path}")
        plot_learning_curves(scalars, path, title=title, note=training_note(level, scalars))


def flyagent_json(summary: dict, reasons: tuple[str, ...] = ("collision", "boundary", "timeout")) -> dict:
    """The eval JSON: episodes, success_rate, failure_rates (one per failure the controller can have, its env's
    ``failure_reasons``: collision, boundary and timeout for a FlyAgent; timeout and burnout for a planner or its
    greedy; and the drones', ``DroneConfig.failures``), tte (steps), and the means per episode of the record's
    extra columns the summary has (:data:`roshan.episode.EXTRA_COLUMNS`, by name)."""
    fr = summary["failure_rates"]
    keys = tuple(reasons)
    out = {"episodes": summary["episodes"], "success_rate": summary["success_rate"],
           "failure_rates": {k: fr.get(k, 0.0) for k in keys},
           "tte": {k: summary["tte"][k] for k in ("mean", "std", "median")}}
    out.update({c.name: summary[c.name]["mean"] for c in EXTRA_COLUMNS if c.name in summary})
    return out


def evaluate_run(target: str | Path, episodes: int = 200, seed: int = 0, num_envs: int | None = None,
                 out_dir: Path | None = None, json_path: Path | None = None, frames_dir: Path | None = None,
                 gif_path: Path | None = None, which: str = "best", progress_bar: bool = True,
                 overrides: list[str] | tuple[str, ...] = (), baseline: str | None = None,
                 replace: bool = False) -> dict:
    """Evaluate a run folder or checkpoint with deterministic actions; files go to ``out_dir`` (default
    ``<run>/eval/<seed>-<episodes>[-<hash of the other settings>]``, see :func:`evaluation_name`; for a shipped
    model ``out/eval/<model>/...``, :func:`eval_root`). An output
    that already holds results is refused unless ``replace``; every summary JSON records its provenance.
    ``overrides`` (``section.key=value``) change the evaluation setting, not the network.
    With ``baseline`` (random | greedy) the scripted policy runs on the same episodes (same seed: same fire
    layouts and wind) and its summary is returned under ``"baseline"``.
    Returns the summary dict of :func:`roshan.runs.report.stats.summarize` plus ``checkpoint`` and ``out_dir``."""
    ensure_taichi()
    _, cfg, agent, path = load_for_acting(target, which, overrides, torch_device())
    use_acting_threads(cfg.train.torch_threads)
    run_dir = path.parent.parent if path.parent.name == "checkpoints" else path.parent
    E = max(1, min(num_envs or cfg.train.eval_envs, episodes))
    arch = current_arch() or "cpu"
    if out_dir is None:
        # what changes the results besides seed and episodes, where it differs from `roshan eval RUN`'s default
        default_envs = max(1, min(cfg.train.eval_envs, episodes))
        settings = {"overrides": list(overrides), "baseline": baseline, "envs": E if E != default_envs else None,
                    "checkpoint": path.name if path != default_checkpoint(run_dir) else None,
                    "arch": arch if arch != "cpu" else None}
        out_dir = eval_root(run_dir) / evaluation_name(seed, episodes, {k: v for k, v in settings.items() if v})
    out = Path(out_dir)
    if not replace:  # refused here, a command creates nothing, not even the folder or its lock
        _refuse_held(out, json_path, frames_dir, gif_path)
    with output_lock(out):  # held until the last file is written: a second evaluation here is refused
        prepare_outputs(out, json_path, frames_dir, gif_path, replace)
        provenance = _provenance(target, path, which, seed, episodes, E, overrides, baseline, arch)
        scratch = None
        if gif_path is not None and frames_dir is None:  # frames only for the GIF: a scratch folder, removed after
            scratch = tempfile.TemporaryDirectory(prefix="roshan_frames_")
            frames_dir = Path(scratch.name)
        env = make_env(cfg, E, seed, evaluation=True, render_mode=None if frames_dir is None else "rgb_array")
        env.caption_name = caption_name(env.default_caption_name, run_dir)
        eps = run_episodes(env, policy_fn(agent), episodes, seed, frames_dir, progress_bar)
        base_eps = None
        kit = kit_of(cfg)
        if baseline is not None:
            base_env, act = kit.baseline(cfg, env, baseline, E, seed, make_env)
            base_eps = run_episodes(base_env, act, episodes, seed, progress_bar=progress_bar)
        notes = setting_notes(cfg.drones, env.drones.farthest_from_bases())
        env.close()
        say = _say if progress_bar else _quiet
        who, reasons, dt = f"{cfg.train.algo} policy", env.failure_reasons, cfg.fire.dt
        summary = write_outputs(eps, out, f"{run_dir.name} ({path.stem}, {len(eps['time'])} episodes, seed {seed})",
                                provenance, reasons, dt, who, say, notes)
        _note_simple_policy(cfg, summary, out)
        write_learning_curves(run_dir, out / "learning_curves.png", f"{run_dir.name}: {who}", cfg.train.level, say)
        payload = flyagent_json(summary, env.failure_reasons)
        if base_eps is not None:
            name, note, extras = kit.baseline_name(baseline, cfg)
            base = write_outputs(base_eps, out / baseline, f"{name} baseline ({len(base_eps['time'])} episodes, "
                                                             f"seed {seed})", provenance, reasons, dt,
                               f"{name} baseline", say, notes)
            plot_comparison({who: eps, baseline: base_eps}, out, reasons=reasons)
            payload = {"policy": payload, baseline: flyagent_json(base, env.failure_reasons)}
            summary["baseline"] = base
            summary["baseline_name"], summary["baseline_note"] = name, note
            payload[baseline].update(extras)
        payload["provenance"] = provenance
        if json_path is not None:
            with writing("the evaluation JSON", json_path):
                Path(json_path).write_text(json.dumps(payload, indent=2) + "\n")
        if gif_path is not None:
            say(f"writing the GIF {gif_path}")
            with writing("the GIF", gif_path):
                write_gif(sorted(Path(frames_dir).glob("frame_*.png")), Path(gif_path))
        if scratch is not None:
            scratch.cleanup()
        summary["checkpoint"], summary["out_dir"] = str(path), str(out)
        return summary


@torch.no_grad()
def save_buffer(target: str | Path, transitions: int, path: Path, seed: int = 0, num_envs: int | None = None,
                which: str = "best", overrides: list[str] | tuple[str, ...] = (),
                progress_bar: bool = True, replace: bool = False) -> str:
    """Record ``transitions`` (drone transitions) of the deterministic policy into a replay buffer file (the IQL
    dataset of docs/model/learning.md §8: raw rewards, per-drone not_done, next observations; the env's ``final_obs`` is
    the next observation where an episode ended, and only a real terminal sets not_done = 0). An existing
    ``path`` is refused unless ``replace``."""
    refuse_overwrite(path, "the replay buffer", replace)
    ensure_taichi()
    trained, cfg, agent, ckpt = load_for_acting(target, which, overrides, torch_device())
    check_model_level("buffer.model", trained.train.level,
                      f"--save-buffer: replay buffers record FlyAgent transitions, but {ckpt}")
    prepare_output(path, "the replay buffer", is_dir=False)
    E = num_envs or cfg.train.eval_envs
    env = FlyVectorEnv(num_envs=E, config=cfg, fly=cfg.fly, seed=seed)
    N = env.num_drones
    obs, _ = env.reset(seed=seed)
    shapes = {k: tuple(v.shape[2:]) for k, v in obs.items()}
    buf = ReplayBuffer(transitions, shapes, device=env.device)
    act = policy_fn(agent)
    bar = new_bar(total=transitions, unit="transition", disable=not progress_bar, desc="buffer")
    while len(buf) < transitions:
        o = {k: v.clone() for k, v in flatten_drones(obs).items()}
        actions = act(o)
        obs, rewards, terms, truncs, info = env.step(actions.view(E, N, 2))
        ended = (terms | truncs).repeat_interleave(N)
        nxt = next_observation(obs, info, ended)
        take = min(E * N, transitions - len(buf))
        not_done = (~terms).repeat_interleave(N).float()
        buf.add({k: v[:take] for k, v in o.items()}, actions[:take], rewards.flatten()[:take], not_done[:take],
                {k: v[:take] for k, v in nxt.items()})
        bar.update(take)
    bar.close()
    with writing("the replay buffer", path):
        buf.save(path)
    return f"wrote {len(buf)} transitions to {path}"
