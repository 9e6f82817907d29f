"""``roshan`` command line: parses options and calls into the package; no logic of its own."""

import contextlib
import json
import math
import sys
from pathlib import Path

import click

from roshan.config import load_config

ARCH = click.option("--arch", type=click.Choice(["cpu", "cuda", "vulkan", "auto"]), default=None,
                    help="Where kernels run (default: config's sim.arch, cpu).")


def _check_threads(ctx, param, value):
    """--threads above the machine's cores is allowed but said: it runs slower, not faster."""
    if value is None:
        return value
    from roshan.runtime import threads_warning  # taichi: imported only when the option is given

    warning = threads_warning(value)
    if warning:
        click.echo(warning, err=True)
    return value


THREADS = click.option("--threads", type=click.IntRange(min=1), default=None, callback=_check_threads,
                       help="CPU threads (default: all cores; more than the machine has run slower).")
def _torch_kernels(ctx, param, value):
    """Apply the reproducible mode (or record that it is off) before the command imports torch."""
    from roshan import reproducible

    try:
        reproducible.enable(reproducible.wanted(value))
    except reproducible.ReproducibleModeError as exc:
        raise click.UsageError(str(exc)) from exc
    return value


REPRODUCIBLE = click.option(
    "--reproducible/--no-reproducible", default=None, callback=_torch_kernels, expose_value=False, is_eager=True,
    help="Torch kernels that give the same weights and figures on every x86-64 CPU, Intel or AMD (the default; "
         "training runs at 0.94-0.98x the speed of this CPU's own kernels); --no-reproducible takes the fastest "
         "kernels this CPU offers, whose results differ by vendor. "
         "ROSHAN_REPRODUCIBLE=0 makes --no-reproducible the default.")
SETS = click.option("--set", "sets", multiple=True, metavar="KEY=VALUE",
                    help="Override a config key, e.g. --set fire.dt=0.05 (repeatable).")
CONFIG = click.option("--config", "-c", "config_path", type=click.Path(dir_okay=False), default=None,
                      help="YAML config (see configs/); defaults are the model's (docs/model/).")


def _fail(exc: Exception) -> None:
    raise click.ClickException(str(exc)) from exc


def _gif_name(ctx, param, value):
    """A --gif file name must end in .gif: the file is a GIF whatever its name, and a viewer goes by the suffix."""
    if value is not None and not str(value).lower().endswith(".gif"):
        raise click.BadParameter(f"{value!r} does not end in .gif (the file written is a GIF)")
    return value


def _number_list(text: str, option: str, kind: type, lowest: float, highest: float | None = None) -> list:
    """``text`` as comma-separated numbers of ``kind`` in [lowest, highest], or a usage error naming ``option``."""
    try:
        values = [kind(x) for x in text.split(",") if x.strip()]
    except ValueError:
        values = []
    bad = [v for v in values if not (lowest <= v <= (math.inf if highest is None else highest))]
    if not values or bad:
        where = f"from {lowest}" + ("" if highest is None else f" to {highest}")
        raise click.BadParameter(f"expected comma-separated {kind.__name__} values {where}, got {text!r}",
                                 param_hint=option)
    return values


def _name_list(ctx, param, value):
    """A comma-separated option as its names (``--maps A,B,C``), or a usage error where it names none."""
    if value is None:
        return None
    names = [x.strip() for x in value.split(",") if x.strip()]
    if not names:
        raise click.BadParameter(f"expected comma-separated names, got {value!r}")
    return names


@contextlib.contextmanager
def reported(*extra: type[Exception]):
    """The one place where what a user's input can cause becomes one line and exit code 1, not a traceback:
    ValueError (ConfigError, MapError, SpecError, OutputError, ... derive from it), OSError (missing, unreadable
    or unwritable files), and ``extra``."""
    try:
        yield
    except (ValueError, OSError, *extra) as exc:
        _fail(exc)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="roshan")
def main():
    """ROSHAN-Taichi: batched FireSPIN wildfire simulation and hierarchical RL for fire-fighting UAVs."""


# ------------------------------------------------------------------------------------------------ simulate


@main.command()
@CONFIG
@click.option("--map", "map_name", default=None, help="Bundled map name, 'uniform', or a GeoTIFF path.")
@click.option("--envs", type=click.IntRange(min=1), default=None, help="Environments advanced together.")
@click.option("--steps", type=click.IntRange(min=0), default=3000, show_default=True, help="Fire updates (dt each).")
@click.option("--seed", type=click.IntRange(min=0), default=None, help="Seed of every random stream.")
@click.option("--fire-percentage", type=float, default=None, help="Fraction of cells ignited at reset (0..1).")
@click.option("--clusters", type=int, default=None, help="Number of fire clusters (or rings).")
@click.option("--pattern", type=click.Choice(["cluster", "scattered", "ring", "random"]), default=None)
@click.option("--wind-speed", type=float, default=None, help="Wind speed (m/s).")
@click.option("--wind-direction", type=float, default=None, help="Degrees from south towards east; -1 = random.")
@click.option("--frames", type=click.Path(file_okay=False), default=None, help="Write PNG frames of env 0 here.")
@click.option("--every", type=click.IntRange(min=1), default=100, show_default=True,
              help="Record statistics (and a frame) every K steps.")
@click.option("--gif", type=click.Path(dir_okay=False), default=None, callback=_gif_name,
              help="Stitch the frames into this GIF.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None,
              help="Write {config, series, timing} (and drones, with --drones) here.")
@click.option("--replace", is_flag=True, help="Overwrite existing --gif / --json files and the frames of a --frames "
              "folder (without it they are refused).")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--drones", type=int, default=None, metavar="N",
              help="Fly N drones per env (FlyAgent envs, complex policy: drones put out the nearest unreserved "
                   "fire); default: the fire alone.")
@click.option("--policy", type=click.Choice(["greedy", "random"]), default=None,
              help="How the drones fly (needs --drones): greedy = straight to the goal (default), random = "
                   "uniform actions.")
@SETS
@ARCH
@THREADS
def simulate(config_path, map_name, envs, steps, seed, fire_percentage, clusters, pattern, wind_speed,
             wind_direction, frames, every, gif, json_path, replace, quiet, drones, policy, sets, arch, threads):
    """Run the fire model on E envs of a map and summarise (optionally frames, a GIF and a JSON series).

    With --drones N every env is a FlyAgent episode whose drones extinguish fires; episodes that end restart
    at once, and the summary adds the episodes finished and their success rate.
    """
    from roshan.tools import simulate as sim_mod

    if policy is not None and drones is None:
        raise click.UsageError("--policy needs --drones N (without drones only the fire is simulated)")

    options = {"map.name": ("--map", map_name), "sim.envs": ("--envs", envs), "sim.seed": ("--seed", seed),
               "ignition.fire_percentage": ("--fire-percentage", fire_percentage),
               "ignition.clusters": ("--clusters", clusters), "ignition.pattern": ("--pattern", pattern),
               "wind.speed": ("--wind-speed", wind_speed), "wind.direction": ("--wind-direction", wind_direction),
               "sim.arch": ("--arch", arch), "sim.threads": ("--threads", threads)}
    with reported():  # an error names the option that gave the value (--wind-speed), --set, or the config file
        cfg = load_config(config_path, list(sets), flags={k: v for k, v in options.items() if v[1] is not None})
        sim_mod.prepare_outputs(Path(frames) if frames else None, Path(gif) if gif else None,
                                Path(json_path) if json_path else None, replace=replace)
        frames_path, gif_path = Path(frames) if frames else None, Path(gif) if gif else None
        if drones is None:  # the fire alone: no envs, no torch (a second less to start)
            result = sim_mod.run_simulation(cfg, steps, every, frames_path, gif_path, progress=not quiet)
        else:
            from roshan.tools.simulate_drones import run_drone_simulation

            result = run_drone_simulation(cfg, steps, drones, policy or "greedy", every, frames_path, gif_path,
                                          progress=not quiet)
    for line in sim_mod.summary_lines(result):
        click.echo(line)
    if json_path:
        with reported():
            sim_mod.write_json(cfg, result, Path(json_path))
        click.echo(f"json: {json_path}")


# ------------------------------------------------------------------------------------------------ maps


@main.group()
def maps():
    """List, inspect and crop CLC+ land-cover maps."""


@maps.command("list")
def maps_list():
    """The bundled sample maps with their sizes."""
    from roshan.maps import bundled_maps, load_map

    for name in bundled_maps():
        m = load_map(name)
        click.echo(f"{name:<18} {m.rows:>4} x {m.cols:<4} cells  {m.rows * m.cell_size / 1000:5.2f} x "
                   f"{m.cols * m.cell_size / 1000:5.2f} km")
    click.echo(f"{'uniform':<18}   50 x 50   cells  generic burnable map (class 16)")


@maps.command("show")
@click.argument("name_or_path")
@click.option("--band", type=click.IntRange(min=1), default=None, help="Band of a multi-band raster.")
@click.option("--bases", type=click.IntRange(1, 4), default=None,
              help="Also where drones.bases = N puts the groundstations on this map, for each corner the first may "
                   "draw, and the farthest cell from its nearest base.")
@click.option("--base-cells", default=None, metavar="'ROW,COL; ROW,COL'",
              help="As --bases, for bases at these cells (drones.base_cells): checked against the map.")
def maps_show(name_or_path, band, bases, base_cells):
    """Size in cells and metres, CRS and class histogram of a map (and, with --bases or --base-cells, where the
    groundstations go)."""
    from roshan.maps import describe_map, load_map

    with reported():
        land = load_map(name_or_path, band=band)
        placed = _bases_lines(land, bases, base_cells) if bases is not None or base_cells is not None else []
        click.echo("\n".join([describe_map(land), *placed]))


def _bases_lines(land, bases: int | None, base_cells: str | None) -> list[str]:
    """Where the groundstations of ``drones.bases`` / ``drones.base_cells`` go on ``land``, as :func:`maps_show`
    prints them; a setting the drones would refuse is refused here the same way."""
    from roshan.config.schema import from_dict
    from roshan.config.sim import DroneConfig, parse_base_cells
    from roshan.kernels.drones import cells_outside, corner_bases, farthest_cell
    from roshan.maps import MIN_BASES_MAP_SIDE

    count = bases or len(parse_base_cells(base_cells or "")) or 1
    cfg = from_dict(DroneConfig, {"bases": count, "base_cells": base_cells or ""})
    rows, cols, cell = land.rows, land.cols, land.cell_size
    if cfg.explicit_bases:
        outside = cells_outside(cfg.explicit_bases, rows, cols)
        if outside:
            raise ValueError(f"--base-cells {base_cells!r}: cell(s) {outside} lie outside {land.name} "
                             f"({rows} x {cols} cells: rows 0-{rows - 1}, columns 0-{cols - 1})")
        placements = (cfg.explicit_bases,)
        lines = [f"Bases:      {count} at the cells given (drones.base_cells), the drones starting at the first:",
                 "  " + ", ".join(f"({r}, {c})" for r, c in cfg.explicit_bases)]
    else:
        if count > 1 and min(rows, cols) < MIN_BASES_MAP_SIDE:
            raise ValueError(f"--bases {count} needs a map of at least {MIN_BASES_MAP_SIDE} x {MIN_BASES_MAP_SIDE} "
                             f"cells; {land.name} has {rows} x {cols}")
        placements = corner_bases(rows, cols, count)
        lines = [f"Bases:      {count} one cell inside corners (drones.bases); the first in the episode's random "
                 "corner, where the drones start:"]
        lines += ["  " + ", ".join(f"({r}, {c})" for r, c in p) for p in placements]
    far = farthest_cell(placements, rows, cols, cell)
    lines.append(f"Farthest:   {far:.0f} m from a cell to its nearest base ({2 * far:.0f} m out and back)")
    return lines


@maps.command("crop")
@click.argument("source")
@click.option("--bounds", nargs=4, type=float, required=True, metavar="W S E N", help="Window to cut out.")
@click.option("--crs", default=None, help="CRS of --bounds (e.g. EPSG:4326); default: the raster's own.")
@click.option("--output", "-o", type=click.Path(dir_okay=False), required=True, help="GeoTIFF to write.")
@click.option("--replace", is_flag=True, help="Overwrite an existing --output file (without it it is refused).")
def maps_crop(source, bounds, crs, output, replace):
    """Cut a window out of a (possibly huge) CLC+ raster (a GeoTIFF path or a bundled map's name), reading only
    that window."""
    from roshan.maps import crop_map, describe_map

    with reported():
        m = crop_map(source, tuple(bounds), output, bounds_crs=crs, replace=replace)
    click.echo(f"wrote {output}")
    click.echo(describe_map(m))


# ------------------------------------------------------------------------------------------------ config


@main.group("config")
def config_group():
    """The config keys that --set and config files take."""


@config_group.command("show")
@click.argument("section", required=False, default="")
def config_show(section):
    """Every config key with its default, type, allowed values and doc; SECTION (e.g. fire, ppo,
    planner.rewards, or one key such as fire.dt) shows only that part."""
    from roshan.config import show_keys

    with reported():
        click.echo(show_keys(section))


# ------------------------------------------------------------------------------------------------ train / eval


@main.command()
@click.argument("config_path", required=False, type=click.Path(dir_okay=False))
@click.option("--name", default=None, help="Run folder name under --root (default: <algo>_<date-time>).")
@click.option("--root", default="runs", show_default=True, type=click.Path(file_okay=False))
@click.option("--resume", "resume_dir", default=None, type=click.Path(file_okay=False),
              help="Continue this run folder from its latest checkpoint (the checkpoint's config, plus --set, "
                   "which later resumes keep).")
@click.option("--no-eval", is_flag=True, help="Skip the evaluation after training.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@SETS
@ARCH
@THREADS
@REPRODUCIBLE
def train(config_path, name, root, resume_dir, no_eval, quiet, sets, arch, threads):
    """Train a FlyAgent (train.algo: ppo, td3 or iql) or the planner over a frozen FlyAgent (train.algo: planner,
    PPO; configs/planner.yaml) from CONFIG (see configs/), or --resume a run.

    Writes runs/<name>/: config.yaml, checkpoints/{latest,best_reward,best_objective}.pt, tb/ (TensorBoard)
    and eval/ (episodes.csv, summary.json, plots). With train.auto_train = k, k runs with seeds seed..seed+k-1
    go to runs/<name>/seed_<s>/.
    """
    from roshan.checkpoints import RunBusy
    from roshan.config import load_run_config
    from roshan.runs import auto_train
    from roshan.runs import train as tr

    options = {"sim.arch": ("--arch", arch), "sim.threads": ("--threads", threads)}
    options = {k: v for k, v in options.items() if v[1] is not None}
    with reported(RunBusy):
        if resume_dir is not None:
            if config_path is not None:
                raise click.UsageError("give either CONFIG or --resume RUN (a resumed run keeps its config)")
            run_dir = Path(resume_dir)
            cfg = tr.resume_config(run_dir, [f"{k}={v}" for k, (_, v) in options.items()] + list(sets))
            results = [tr.train(cfg, run_dir, resume=True, progress_bar=not quiet, evaluate_at_end=not no_eval)]
        else:  # an error names where the bad value came from: CONFIG, --set or the option
            cfg = load_run_config(config_path, list(sets), flags=options)
            results = auto_train.train_auto(cfg, root, name, progress_bar=not quiet, evaluate_at_end=not no_eval)
    for res in results:
        click.echo(auto_train.result_lines(res))


@main.command("eval")
@click.argument("target", type=click.Path(exists=True))
@click.option("--episodes", type=click.IntRange(min=1), default=200, show_default=True)
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Env seed (fire layouts).")
@click.option("--envs", type=click.IntRange(min=1), default=None, help="Envs run together (default: train.eval_envs).")
@click.option("--checkpoint", "which", default="best",
              type=click.Choice(["best", "best_eval", "best_objective", "best_reward", "latest"]), show_default=True,
              help="Which checkpoint of a run folder; best = best_eval (periodic evaluation) if the run has one, "
                   "else best_objective.")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Folder for episodes.csv, summary.json, plots (default: RUN/eval/<seed>-<episodes>[-<hash of "
                   "the other settings>]; for a model shipped in models/, out/eval/<model>/...).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None,
              help="Write {episodes, success_rate, failure_rates, tte, provenance} here.")
@click.option("--replace", is_flag=True,
              help="Overwrite an evaluation already in the output folder (and --json/--gif/--frames files, or "
                   "the --save-buffer FILE); without it such outputs are refused.")
@click.option("--frames", "frames_dir", type=click.Path(file_okay=False), default=None,
              help="PNG frames of env 0's first episode.")
@click.option("--gif", "gif_path", type=click.Path(dir_okay=False), default=None, callback=_gif_name,
              help="GIF of env 0's first episode.")
@click.option("--baseline", type=click.Choice(["random", "greedy", "clairvoyant"]), default=None,
              help="Also run this scripted policy on the same episodes and print both side by side. A planner's "
                   "clairvoyant reference sees every burning cell from the start and assigns drones to fires by the "
                   "least summed flight time each decision.")
@click.option("--save-buffer", nargs=2, type=(click.IntRange(min=1), click.Path(dir_okay=False)), default=None,
              metavar="N FILE", help="Instead: record N transitions of the deterministic policy (an IQL dataset).")
@click.option("--maps", default=None, callback=_name_list, metavar="A,B,C",
              help="A map suite: one evaluation per map (bundled name or GeoTIFF path) in DIR/<map>/, and "
                   "DIR/maps.md and maps.json with one row per map (DIR: --out, else beside single evaluations as "
                   "maps-<seed>-<episodes>-<hash>).")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@SETS
@ARCH
@THREADS
@REPRODUCIBLE
def eval_cmd(target, episodes, seed, envs, which, out_dir, json_path, replace, frames_dir, gif_path, baseline,
             save_buffer, maps, quiet, sets, arch, threads):
    """Evaluate a trained FlyAgent or planner (a run folder or a checkpoint file) with deterministic actions.

    Prints a thesis-style table (success rate with its Wilson interval, failure reasons, TTE mean ± std
    (median)); --set changes the evaluation setting (e.g. --set ignition.fire_percentage=0.05). For a planner
    run, --baseline greedy plays the heuristic controller on the same episodes (same seed and envs).

    Files go to a new folder per setting, RUN/eval/<seed>-<episodes>[-<hash>] (the hash covers --set, --baseline,
    --checkpoint, --envs, --arch where they differ from the defaults; a model shipped in models/ has its folders in
    out/eval/<model>/ instead, so the checkout stays clean); an output that already holds results is
    refused unless --replace. Every summary JSON records the command, overrides, checkpoint and code version.

    --maps A,B,C evaluates on each map as --set map.name=MAP would, prints each map's table as it ends and then
    one row per map (success, median TTE, drones lost where drones can come down, ratio of the median TTEs).
    """
    if maps is not None:
        single = [name for name, value in (("--frames", frames_dir), ("--gif", gif_path), ("--json", json_path),
                                           ("--save-buffer", save_buffer)) if value is not None]
        if single:
            raise click.UsageError(f"--maps cannot be combined with {', '.join(single)} (they are for a single "
                                   "evaluation; a map suite writes DIR/<map>/ and DIR/maps.json)")
        _eval_maps(target, maps, episodes, seed, envs, which, out_dir, replace, baseline, quiet, sets, arch, threads)
        return
    from roshan.runs import evaluate as ev
    from roshan.runtime import init_taichi

    with reported():
        init_taichi(arch or "cpu", threads)
        if save_buffer is not None:
            n, path = save_buffer
            click.echo(ev.save_buffer(target, n, Path(path), seed=seed, num_envs=envs, which=which, overrides=sets,
                                      progress_bar=not quiet, replace=replace))
            return
        summary = ev.evaluate_run(target, episodes=episodes, seed=seed, num_envs=envs,
                                  out_dir=Path(out_dir) if out_dir else None,
                                  json_path=Path(json_path) if json_path else None,
                                  frames_dir=Path(frames_dir) if frames_dir else None,
                                  gif_path=Path(gif_path) if gif_path else None, which=which,
                                  progress_bar=not quiet, overrides=sets, baseline=baseline, replace=replace)
    _echo_evaluation(summary, f"{target} ({Path(summary['checkpoint']).stem}, seed {seed})", baseline)
    click.echo(f"files: {summary['out_dir']}")


def _echo_evaluation(summary: dict, title: str, baseline: str | None) -> None:
    """An evaluation's table; with a baseline both side by side, the column naming which one played (the
    planner's greedy: original or fixed), and its note under the table."""
    from roshan.runs.report.tables import format_comparison, format_table

    if baseline is not None:
        click.echo(format_comparison({"policy": summary, summary.get("baseline_name", baseline): summary["baseline"]},
                                     title))
        if summary.get("baseline_note"):
            click.echo(summary["baseline_note"])
    else:
        click.echo(format_table(summary, title))
    if summary.get("note"):
        click.echo(summary["note"])


def _eval_maps(target, maps, episodes, seed, envs, which, out_dir, replace, baseline, quiet, sets, arch, threads):
    """``roshan eval TARGET --maps A,B,C``: each map's table as it ends, then the suite's."""
    from roshan.runs.map_suite import evaluate_maps
    from roshan.runtime import init_taichi

    def echo_map(name: str, summary: dict) -> None:
        _echo_evaluation(summary, f"{target} on {name} ({Path(summary['checkpoint']).stem}, seed {seed})", baseline)
        click.echo(f"files: {summary['out_dir']}\n")

    with reported():
        init_taichi(arch or "cpu", threads)
        suite = evaluate_maps(target, maps, episodes=episodes, seed=seed, num_envs=envs,
                              out_dir=Path(out_dir) if out_dir else None, which=which, progress_bar=not quiet,
                              overrides=sets, baseline=baseline, replace=replace, on_map=echo_map)
    click.echo(suite["table"])
    click.echo(f"files: {suite['out_dir']} (maps.md, maps.json, one folder per map)")


@main.command()
@click.argument("target", type=click.Path(exists=True))
@click.option("--steps", type=click.IntRange(min=1), default=None,
              help="Env steps to run (planner: decisions); default: until the window is closed, or without a "
                   "display env 0's first episode.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Env seed (fire layouts).")
@click.option("--checkpoint", "which", default="best",
              type=click.Choice(["best", "best_eval", "best_objective", "best_reward", "latest"]), show_default=True)
@click.option("--fps", type=click.FloatRange(min=0.1), default=10.0, show_default=True,
              help="Frames a second, at most.")
@click.option("--gif", "gif_path", type=click.Path(dir_okay=False), default="out/watch.gif", show_default=True,
              callback=_gif_name,
              help="Where the frames go when no window can be shown.")
@click.option("--screenshot", type=click.Path(dir_okay=False), default=None,
              help="Save the last frame as this PNG: the window's, or without a display the GIF's last frame.")
@click.option("--replace", is_flag=True, help="Overwrite an existing --gif or --screenshot file (without it they are "
              "refused).")
@SETS
@ARCH
@THREADS
@REPRODUCIBLE
def watch(target, steps, seed, which, fps, gif_path, screenshot, replace, sets, arch, threads):
    """Watch a trained FlyAgent or planner (a run folder or checkpoint) fly, live in a window (like RL-Zoo's
    enjoy); without a display, env 0's first episode is written as a GIF instead."""
    from roshan.runs.watch import watch as run_watch
    from roshan.runtime import init_taichi

    with reported():
        init_taichi(arch or "cpu", threads)
        click.echo(run_watch(target, steps=steps, seed=seed, which=which, fps=fps, gif_path=Path(gif_path),
                             screenshot=Path(screenshot) if screenshot else None, overrides=sets, replace=replace))


# ------------------------------------------------------------------------------------------------ study


class _StudyGroup(click.Group):
    """``roshan study CONFIG ...`` means ``roshan study run CONFIG ...``; ``report`` is the other subcommand."""

    def parse_args(self, ctx, args):
        if args and args[0] not in self.commands and args[0] not in ctx.help_option_names:
            args = ["run", *args]
        return super().parse_args(ctx, args)


@main.group(cls=_StudyGroup)
def study():
    """Optuna studies: `roshan study CONFIG --space SPACE.yaml --trials N` (= `study run`), `study report`."""


@study.command("run")
@click.argument("config_path", required=False, type=click.Path(dir_okay=False))
@click.option("--space", "space_path", type=click.Path(dir_okay=False), default=None,
              help="Search space YAML: dotted config keys -> ranges (configs/spaces/).")
@click.option("--trials", type=click.IntRange(min=1), default=None,
              help="Trials to finish (stored with the study; given with --resume it changes the budget).")
@click.option("--storage", default=None,
              help="SQLAlchemy URL (postgresql://user:password@host/db) shared by machines, or a journal file "
                   "(default: ROOT/NAME/study.journal).")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Worker processes on this machine (one trial each at a time).")
@click.option("--name", default=None, help="Study name (default: <config>-<space>).")
@click.option("--root", default="runs", show_default=True, type=click.Path(file_okay=False),
              help="Trials train in ROOT/NAME/trial_<n>/.")
@click.option("--resume", is_flag=True, help="Continue the study (or join it from another machine).")
@click.option("--objective", type=click.Choice(["success", "reward", "tte"]), default=None,
              help="Evaluation success rate (default), mean reward, or time to end (minimised, no pruning).")
@click.option("--seed", type=click.IntRange(min=0), default=None, help="TPE seed (default 42).")
@click.option("--startup-trials", type=click.IntRange(min=0), default=None, help="Random trials before TPE (15).")
@click.option("--prune/--no-prune", default=None, help="Median pruning on the training objective (default on).")
@click.option("--prune-startup", type=click.IntRange(min=0), default=None, help="Trials before pruning starts (5).")
@click.option("--prune-warmup", type=click.IntRange(min=0), default=None, help="Updates before a trial can be "
              "pruned (10).")
@click.option("--max-retry", type=click.IntRange(min=0), default=3, show_default=True,
              help="Retries of a trial whose worker died.")
@click.option("--heartbeat", type=click.IntRange(min=1), default=60, show_default=True,
              help="Seconds between a running trial's heartbeats; stale after 5 missed ones.")
@click.option("--quiet", is_flag=True, help="No progress bars.")
@click.option("--worker", is_flag=True, hidden=True)
@click.option("--slot", type=click.IntRange(min=0), default=0, hidden=True)
@SETS
@ARCH
@THREADS
@REPRODUCIBLE
def study_run(config_path, space_path, trials, storage, workers, name, root, resume, objective, seed, startup_trials,
              prune, prune_startup, prune_warmup, max_retry, heartbeat, quiet, worker, slot, sets, arch, threads):
    """Tune any config keys with Optuna (TPE, median pruning); the study survives crashes and spreads over
    machines through a shared --storage (README: Multi-machine Optuna study)."""
    from roshan.study.runner import start_study
    from roshan.study.trial import local_values, run_worker

    with reported():
        if worker:
            sys.exit(run_worker(storage, name, root, slot, local_values(arch, threads), quiet, heartbeat, max_retry))
        start_study(config_path, space_path, sets, name=name, root=root, storage=storage, resume=resume,
                    trials=trials, workers=workers, arch=arch, threads=threads, quiet=quiet, heartbeat=heartbeat,
                    max_retry=max_retry, echo=click.echo, objective=objective, seed=seed,
                    startup_trials=startup_trials, prune=prune, prune_startup=prune_startup,
                    prune_warmup=prune_warmup)


@study.command("report")
@click.argument("target")
@click.option("--name", default=None, help="Which study of a storage URL that holds several.")
@click.option("--root", default="runs", show_default=True, type=click.Path(file_okay=False))
@click.option("--top-k", type=click.IntRange(min=1), default=10, show_default=True,
              help="Trials averaged into top<k>_mean.yaml (the thesis used 10).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Report folder (default: ROOT/NAME/report).")
@click.option("--no-plots", is_flag=True)
def study_report(target, name, root, top_k, out_dir, no_plots):
    """Best trials of a study (a name under --root, a study folder, or a storage URL), the mean of the top-k
    trials' parameters as a ready config YAML, and Optuna's plots."""
    from roshan.study.report import open_for_report, write_report

    with reported():
        stu, default_out = open_for_report(target, root, name)
        rep = write_report(stu, Path(out_dir) if out_dir else default_out, top_k, plots=not no_plots)
    click.echo(f"study {stu.study_name}: {len(stu.trials)} trials; the best completed:")
    click.echo(rep["table"])
    for path in rep["files"]:
        click.echo(f"wrote {path}")
    for plot, where in rep["plots"].items():
        click.echo(f"{plot}: {where}")


# ------------------------------------------------------------------------------------------------ experiment


@main.group()
def experiment():
    """Conditions x seeds from a spec (configs/experiments/): `experiment run SPEC`, `experiment report SPEC`."""


EXPERIMENT_STORAGE = click.option(
    "--storage", default=None, help="SQLAlchemy URL (postgresql://user:password@host/db) shared by machines, or a "
                                    "journal file (default: the spec's storage, else ROOT/NAME/experiment.journal).")
BUDGET = click.option("--budget", type=click.Choice(["local", "thesis"]), default="local", show_default=True,
                      help="The spec's budgets for this machine, or the thesis's own (each condition's thesis_set; "
                           "a separate experiment, NAME-thesis-budget).")


@experiment.command("run")
@click.argument("spec_path", type=click.Path(dir_okay=False))
@BUDGET
@EXPERIMENT_STORAGE
@click.option("--root", default="runs", show_default=True, type=click.Path(file_okay=False),
              help="Runs train in ROOT/NAME/<condition>/seed_<s>/.")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Worker processes on this machine (one run each at a time). Default: one per core, each run "
                   "on one thread (--threads N: cores / N workers); runs give the same results however they "
                   "share the machine.")
@click.option("--max-retry", type=click.IntRange(min=0), default=3, show_default=True,
              help="Retries of a run whose worker died (each continues from its latest checkpoint).")
@click.option("--heartbeat", type=click.IntRange(min=1), default=60, show_default=True,
              help="Seconds between a running run's heartbeats; stale after 5 missed ones.")
@click.option("--only", multiple=True, metavar="CONDITION",
              help="Run only these conditions (names or shell patterns such as 'E2_*'; repeat for more); the "
                   "others stay queued for a later call or another machine.")
@click.option("--rerun", multiple=True, metavar="CONDITION[/seed_S]",
              help="Run these conditions' finished runs, or these runs, once more with the code here now (names or "
                   "patterns, such as 'E5' or 'E5*/seed_[012]'; the newest result is reported, earlier ones stay in "
                   "the journal).")
@click.option("--remake", multiple=True, metavar="CONDITION[/seed_S]",
              help="Make these runs again under the settings the spec now gives them, which differ from those their "
                   "results were made with (names or patterns as for --rerun): their earlier results leave the "
                   "report and stay in the journal. Without it such a spec is refused.")
@click.option("--worker", is_flag=True, hidden=True)
@click.option("--slot", type=click.IntRange(min=0), default=0, hidden=True)
@ARCH
@THREADS
@REPRODUCIBLE
def experiment_run(spec_path, budget, storage, root, workers, max_retry, heartbeat, only, rerun, remake, worker, slot,
                   arch, threads):
    """Train and evaluate every (condition, seed) of SPEC; run it again to continue after a crash (finished runs
    are kept, a killed one continues from its checkpoint); machines sharing --storage split the runs."""
    from roshan.experiment.runner import run_experiment, run_storage, run_worker, spec_storage
    from roshan.experiment.spec import load_spec
    from roshan.runtime import share_cores
    from roshan.study.trial import local_values

    with reported():
        spec = load_spec(spec_path, budget)
        chosen = spec.select(only)
        if not worker:
            workers, threads = share_cores(workers, threads)
        extra = tuple(f"{k}={v}" for k, v in local_values(arch, threads).items())
        if worker:
            url = run_storage(spec, root, storage)
            sys.exit(run_worker(spec, url, root, heartbeat=heartbeat, max_retry=max_retry, extra=extra, only=chosen))
        args = (["--arch", arch] if arch else []) + (["--threads", str(threads)] if threads else [])
        run_experiment(spec, root, storage, workers, args, heartbeat, max_retry, echo=click.echo, only=chosen,
                       rerun=spec.select_runs(rerun) if rerun else (),
                       remake=spec.select_runs(remake, "--remake") if remake else ())
        # the report reads the spec's journal by default: name the copy the runs went to when it is another
        used = run_storage(spec, root, storage)
        named = used if storage or used != spec_storage(spec, root) else None
    click.echo(f"report: roshan experiment report {spec_path}" + (f" --budget {budget}" if budget != "local" else "")
               + (f" --storage {named}" if named else "") + (f" --root {root}" if root != "runs" else ""))


@experiment.command("carry")
@click.argument("source_path", type=click.Path(dir_okay=False))
@click.argument("spec_path", type=click.Path(dir_okay=False))
@click.option("--source-storage", default=None, help="SOURCE's journal or URL (default: its spec's storage).")
@EXPERIMENT_STORAGE
@click.option("--root", default="runs", show_default=True, type=click.Path(file_okay=False))
@click.option("--only", multiple=True, metavar="CONDITION", help="Carry only these conditions (names or patterns).")
def experiment_carry(source_path, spec_path, source_storage, storage, root, only):
    """Record SOURCE's finished runs as SPEC's, for the conditions both specs hold with the same settings: rows
    that move to an experiment of their own keep their results (SOURCE's journal is only read; SPEC's committed
    journal is written only when --storage names it, as with `experiment run`)."""
    from roshan.experiment.runner import carry_results, load_experiment, run_storage, spec_storage
    from roshan.experiment.spec import load_spec
    from roshan.study.storage import open_storage

    with reported():
        source, spec = load_spec(source_path), load_spec(spec_path)
        chosen = spec.select(only)
        origin = load_experiment(open_storage(spec_storage(source, root, source_storage), heartbeat=None),
                                 source.name)
        target = open_storage(run_storage(spec, root, storage, click.echo), heartbeat=None)
        carry_results(origin, spec, target, chosen, echo=click.echo)


@experiment.command("report")
@click.argument("spec_path", type=click.Path(dir_okay=False))
@BUDGET
@EXPERIMENT_STORAGE
@click.option("--root", default="runs", show_default=True, type=click.Path(file_okay=False))
@click.option("--out", "out_dir", type=click.Path(file_okay=False), default=None,
              help="Report folder (default: ROOT/NAME/report); one that holds a report's files (an earlier report, "
                   "an evaluation's summary.json) is refused unless --replace.")
@click.option("--replace", is_flag=True, help="Overwrite the report's files in --out (an earlier report, or files "
              "another command wrote).")
def experiment_report(spec_path, budget, storage, root, out_dir, replace):
    """Thesis-style tables of SPEC's finished runs (mean ± std (median) over seeds beside the thesis's values),
    per-seed rows (CSV, JSON) and a plot."""
    from roshan.experiment.report import report_experiment

    with reported():
        click.echo(report_experiment(spec_path, budget, storage, root, out_dir, replace))


# ------------------------------------------------------------------------------------------------ bench


@main.group()
def bench():
    """Reproducible benchmarks (see BENCHMARKS.md)."""


@bench.command("fidelity")
@click.option("--seeds", type=click.IntRange(min=1), default=20, show_default=True)
@click.option("--condition", "conditions", multiple=True, help="Only these reference conditions (CSV stems).")
@click.option("--every", type=click.IntRange(min=500), default=5000, show_default=True, help="Table row spacing.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None, help="PNG of every curve.")
@ARCH
@THREADS
def bench_fidelity(seeds, conditions, every, json_path, plot_path, arch, threads):
    """Fire statistics against the original's (shared/reference): our seed means vs its seed band."""
    from roshan.runtime import init_taichi
    from roshan.tools import bench as b

    init_taichi(arch or "cpu", threads)
    conds = [c for c in b.FIDELITY_CONDITIONS if not conditions or c.name in conditions]
    if not conds:
        _fail(ValueError(f"--condition: none of {conditions}; known: {[c.name for c in b.FIDELITY_CONDITIONS]}"))
    with reported():
        results = b.fidelity(seeds, conds)
    for name, res in results.items():
        click.echo(b.format_fidelity_table(name, res, every))
    if json_path:
        Path(json_path).write_text(json.dumps(results, indent=1))
    if plot_path:
        click.echo(f"plot: {b.plot_fidelity(results, Path(plot_path))}")


@bench.command("fire")
@click.option("--envs", "env_counts", default="1,16,64,256,1024", show_default=True, help="Comma-separated E values.")
@click.option("--steps", type=click.IntRange(min=1), default=50_000, show_default=True,
              help="Timed updates per run, from a reset (the original: mean over 50,000).")
@click.option("--warmup", type=click.IntRange(min=0), default=100, show_default=True,
              help="Untimed updates (compiles).")
@click.option("--big/--no-big", default=True, show_default=True,
              help="Also one env on Borkenberge and a 941k-cell map (Haard's size).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
@ARCH
@THREADS
def bench_fire(env_counts, steps, warmup, big, json_path, arch, threads):
    """Fire-model throughput: env-steps/s and burning-cell updates/s against the original's figures."""
    from roshan.runtime import init_taichi
    from roshan.tools import bench as b

    counts = _number_list(env_counts, "--envs", int, lowest=1)
    used = init_taichi(arch or "cpu", threads)
    click.echo(f"timing {2 * len(counts) + 2 * big} runs; each row as it finishes:", err=True)
    click.echo(b.FIRE_SPEED_HEADER, err=True)
    with reported():
        report = b.fire_speed(counts, steps, warmup, big=big, arch=used, threads=threads,
                              on_row=lambda r: click.echo(b.format_fire_row(r), err=True))
    click.echo(b.format_fire_speed(report))
    if json_path:
        Path(json_path).write_text(json.dumps(report, indent=1))


@bench.command("memory")
@click.option("--steps", type=click.IntRange(min=1), default=50_000, show_default=True,
              help="Updates per episode of the 1.5 % fire; the 35 % rows run a tenth of them.")
@click.option("--rss-envs", type=click.IntRange(min=0), default=64, show_default=True,
              help="Envs of the 941k-cell map in a fresh process whose peak RSS is measured (0 = skip).")
@click.option("--rss-steps", type=click.IntRange(min=1), default=500, show_default=True)
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
@ARCH
@THREADS
def bench_memory(steps, rss_envs, rss_steps, json_path, arch, threads):
    """Fire memory per env and reset cost, sparse against dense: 35x36_Woods, Borkenberge, 941k cells (auto
    picks sparse there once the dense records of all envs would take over 1 GiB).

    A reset after an episode of --steps updates (median of 3 episodes; one at 35 %) in its two halves: "clear"
    forgets the last episode (what the sparse layout makes follow the footprint), "fires" lights the new ones."""
    from roshan.runtime import init_taichi
    from roshan.tools import bench as b

    used = init_taichi(arch or "cpu", threads)
    report = b.memory_report(steps, rss_envs, rss_steps, used, threads, click.echo)
    if json_path:
        Path(json_path).write_text(json.dumps(report, indent=1))


@bench.command("env")
@click.option("--envs", "env_counts", default="1,64,256,1024,4096", show_default=True, help="Comma-separated E.")
@click.option("--drones", type=click.IntRange(min=1), default=4, show_default=True)
@click.option("--fire", "fire_percentages", default="0.015,0.35", show_default=True, help="Ignition fractions.")
@click.option("--policies", default="random,simple,collision,collision+ppo", show_default=True,
              help="random (env only), simple / collision (+ untrained FlyAgent network inference), fly_collision "
                   "(+ the shipped trained collision FlyAgent, deterministic), simple+ppo / collision+ppo (+ the "
                   "PPO update of configs/fly_*.yaml).")
@click.option("--min-env-steps", type=click.IntRange(min=1), default=100_000, show_default=True,
              help="Timed env-steps per run (the collision network runs a quarter).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
@ARCH
@THREADS
def bench_env(env_counts, drones, fire_percentages, policies, min_env_steps, json_path, arch, threads):
    """FlyAgent env throughput: env only, and with FlyAgent network inference, against the original."""
    from roshan.runtime import init_taichi
    from roshan.tools import bench as b

    counts = _number_list(env_counts, "--envs", int, lowest=1)
    pcts = _number_list(fire_percentages, "--fire", float, lowest=0.0, highest=1.0)
    init_taichi(arch or "cpu", threads)
    pols = [None if p == "random" else p for p in policies.split(",") if p.strip()]
    known = (None, "simple", "collision", "fly_collision", "simple+ppo", "collision+ppo")
    unknown = [p for p in pols if p not in known]
    if unknown:
        _fail(ValueError(f"--policies: unknown {unknown}; expected random, simple, collision, fly_collision, "
                         "simple+ppo, collision+ppo"))
    click.echo(f"timing {len(counts) * len(pcts) * len(pols)} runs; each row as it finishes:", err=True)
    click.echo(b.ENV_SPEED_HEADER, err=True)
    report = b.env_speed(counts, drones, pcts, pols, min_env_steps=min_env_steps,
                         on_row=lambda r: click.echo(b.format_env_row(r), err=True))
    click.echo(b.format_env_speed(report))
    if json_path:
        Path(json_path).write_text(json.dumps(report, indent=1))


@bench.command("train")
@click.option("--families", default="E1,E6,TD3,planner", show_default=True, callback=_name_list,
              help="Recipe families: E1 (simple FlyAgent, PPO), E6 (collision FlyAgent, PPO), TD3, planner (P3, "
                   "interval 5); each is its condition of the thesis spec.")
@click.option("--modes", default="reproducible,vendor", show_default=True, callback=_name_list,
              help="Torch kernels: reproducible (the same on every CPU; the default of train) and/or vendor "
                   "(--no-reproducible).")
@click.option("--updates", type=click.IntRange(min=1), default=2, show_default=True,
              help="Timed updates per slice, after one untimed warm-up update.")
@click.option("--rounds", type=click.IntRange(min=1), default=1, show_default=True,
              help="Times each slice runs (interleaved); the summary takes medians.")
@click.option("--against", type=click.Path(file_okay=False, exists=True), default=None,
              help="Another checkout (say, a git worktree of an older commit) timed with the same slices in the "
                   "same run.")
@click.option("--spec", "spec_path", default="configs/experiments/thesis.yaml", show_default=True,
              help="The experiment spec whose conditions are timed. A relative path is read in each checkout, so "
                   "each code runs its own spec; an existing file given by its absolute path is read by both, so "
                   "both codes run one workload (a spec whose settings or models changed times other work).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None)
@click.option("--threads", type=click.IntRange(min=1), default=1, show_default=True, callback=_check_threads,
              help="CPU threads of Taichi and torch in each slice (the experiment runner's --threads 1).")
def bench_train(families, modes, updates, rounds, against, spec_path, json_path, threads):
    """Training speed: a fixed slice of each recipe family (env-steps/s all told, the split into collection,
    update and the rest, the periodic evaluation's cost, peak memory), in each torch mode."""
    from roshan.tools import train_bench as tb

    bad = [f for f in families if f not in tb.FAMILIES] + [m for m in modes if m not in tb.MODES]
    if bad:
        _fail(ValueError(f"bench train: unknown {bad}; families: {', '.join(tb.FAMILIES)}; modes: "
                         f"{', '.join(tb.MODES)}"))
    if Path(spec_path).is_absolute() and not Path(spec_path).is_file():
        _fail(ValueError(f"bench train: --spec {spec_path}: no such file (an absolute path is read by both codes)"))
    click.echo(tb.HEADER, err=True)
    with reported(RuntimeError):
        report = tb.bench_training(families, modes, updates, rounds, Path(against) if against else None,
                                   spec=spec_path, threads=threads,
                                   on_row=lambda r: click.echo(tb.format_row(r), err=True))
    click.echo("\n".join(tb.ratios(report)))
    if json_path:
        Path(json_path).write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    sys.exit(main())
