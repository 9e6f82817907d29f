"""A map suite: ``roshan eval RUN --maps A,B,C`` evaluates a run on several maps and sums the results up per map.

Each map is one evaluation exactly as ``roshan eval RUN --set map.name=MAP`` makes it (:func:`evaluate_run`:
same episodes, seed, baseline and overrides), written to its own folder ``DIR/<map>/``. ``DIR/maps.md`` and
``DIR/maps.json`` then hold one row per map: its size, each controller's success rate and median TTE, the mean of
each extra column of the record that has a row in the tables (drones lost) where the drones counted it, and the
ratio of the median TTEs. Every map is loaded and checked before the first evaluation starts, so a misspelt third
map does not cost the first two evaluations.
"""

import json
import shlex
from collections.abc import Callable, Sequence
from pathlib import Path

from tqdm import tqdm

from roshan.checkpoints import config_of_checkpoint, load_checkpoint, resolve_checkpoint
from roshan.config import Config, apply_overrides
from roshan.episode import EXTRA_COLUMNS
from roshan.io import OutputError, write_atomic, writing
from roshan.maps import LandCoverMap, MapError, check_drone_map, load_map
from roshan.runs.evaluate import default_checkpoint, eval_root, evaluate_run, evaluation_name, held_results, output_lock
from roshan.runs.levels import kit_of
from roshan.runs.report.notes import ratio_is_meaningful
from roshan.runtime import current_arch

SUMMARY_FILES = ("maps.md", "maps.json")


def _map_override(spec: str) -> str:
    return f"map.name={spec}"


def run_config(target: str | Path, which: str = "best") -> tuple[Config, Path]:
    """(config, checkpoint path) of a run folder or checkpoint, without building its networks."""
    path = resolve_checkpoint(target, which)
    return config_of_checkpoint(load_checkpoint(path), str(path)), path


def check_maps(maps: Sequence[str], trained: Config, overrides: Sequence[str] = ()) -> dict[str, LandCoverMap]:
    """Load every map of ``maps`` in the evaluation setting (``trained`` plus ``overrides``) and refuse, before any
    episode runs, one that cannot be evaluated: unknown or unreadable, too small for the drones or the fire
    percentage, nothing that burns (a MapError naming the map), or two maps that would share a folder.
    Returns folder name -> map, in the order given."""
    if any(o.split("=", 1)[0].strip() == "map.name" for o in overrides):
        raise ValueError("--maps sets map.name for each map; leave --set map.name=... out")
    lands: dict[str, LandCoverMap] = {}
    for spec in maps:
        cfg = apply_overrides(trained, [*overrides, _map_override(spec)])
        try:
            land = load_map(cfg.map.name, band=cfg.map.band or None, rows=cfg.map.uniform_rows,
                            cols=cfg.map.uniform_cols)
            check_drone_map(land, cfg.ignition.fire_percentage, cfg.train.level.fights_fire(cfg),
                            f"a {cfg.train.algo} evaluation", cfg.drones.bases)
            kit_of(cfg).check_map(land, cfg)
        except MapError as exc:
            raise MapError(f"--maps: map {spec!r} cannot be evaluated: {exc}") from exc
        if land.name in lands:
            raise MapError(f"--maps: {spec!r} and {lands[land.name].source or land.name} would share the folder "
                           f"{land.name!r}; give each map once, or rename one of the files")
        lands[land.name] = land
    return lands


def suite_folder(run_dir: Path, checkpoint: Path, trained: Config, maps: Sequence[str], seed: int, episodes: int,
                 num_envs: int | None, overrides: Sequence[str], baseline: str | None) -> Path:
    """Where a suite goes without ``--out``: beside the run's single evaluations (:func:`eval_root`), named
    ``maps-<seed>-<episodes>-<hash>``, the hash covering the maps and whatever else differs from the defaults
    of ``roshan eval RUN`` (overrides, baseline, envs, checkpoint, arch), as :func:`evaluation_name` names them."""
    default_envs = max(1, min(trained.train.eval_envs, episodes))
    envs = max(1, min(num_envs or trained.train.eval_envs, episodes))
    arch = current_arch() or "cpu"
    settings = {"maps": list(maps), "overrides": list(overrides), "baseline": baseline,
                "envs": envs if envs != default_envs else None,
                "checkpoint": checkpoint.name if checkpoint != default_checkpoint(run_dir) else None,
                "arch": arch if arch != "cpu" else None}
    return eval_root(run_dir) / f"maps-{evaluation_name(seed, episodes, {k: v for k, v in settings.items() if v})}"


def refuse_held_suite(out_dir: Path, names: Sequence[str]) -> None:
    """Without --replace: refuse a suite folder whose map folders hold evaluations or that holds a suite summary
    (:class:`OutputError` naming them and the two ways out), before anything is created."""
    held = [f"{name}/{f}" for name in names for f in held_results(out_dir / name)]
    held += [f for f in SUMMARY_FILES if (out_dir / f).is_file()]
    if held:
        raise OutputError("the map suite", out_dir, f"it already holds evaluations ({', '.join(held)}); give "
                                                    "--replace to overwrite them, or --out DIR to write a new folder")


# The record's extra columns a suite shows, a mean per controller and map: those with a row in the tables.
SUITE_COLUMNS = tuple(c for c in EXTRA_COLUMNS if c.label)


def controller_figures(summary: dict) -> dict:
    """One controller's figures of a map's summary: success rate (with its Wilson interval), median TTE in steps
    and seconds, and the mean per episode of each extra column with a label (:data:`SUITE_COLUMNS`) the summary
    has."""
    figures = {"success_rate": summary["success_rate"], "success_ci": list(summary["success_ci"]),
               "tte_median": summary["tte"]["median"],
               "tte_median_seconds": summary.get("tte_seconds", {}).get("median")}
    figures.update({c.name: summary[c.name]["mean"] for c in SUITE_COLUMNS if c.name in summary})
    return figures


def map_row(name: str, land: LandCoverMap, summary: dict) -> dict:
    """The summary row of one map's evaluation (``summary`` as :func:`evaluate_run` returns it)."""
    row = {"map": name, "source": str(land.source) if land.source else name, "rows": land.rows, "cols": land.cols,
           "cells": land.rows * land.cols, "episodes": summary["episodes"], "folder": name,
           "policy": controller_figures(summary)}
    notes = list(summary.get("notes", ()))
    if "baseline" in summary:
        row["baseline"] = {"name": summary["baseline_name"], **controller_figures(summary["baseline"])}
        mine, theirs = row["policy"]["tte_median"], row["baseline"]["tte_median"]
        meaningful = ratio_is_meaningful(summary, summary["baseline"])
        row["tte_median_ratio"] = mine / theirs if meaningful and mine is not None and theirs else None
        notes += [n for n in summary["baseline"].get("notes", ()) if n not in notes]
        if not meaningful:  # with no success, a controller's median TTE is its time limit
            row["tte_median_ratio_note"] = NO_SUCCESS
    if notes:
        row["notes"] = notes
    return row


def suite_command(map_provenance: dict, maps: Sequence[str]) -> str:
    """The ``roshan eval RUN --maps A,B,C ...`` that reproduces the suite: a map's own command (from its
    provenance, whose last override is its map) with that ``--set map.name=...`` replaced by ``--maps``."""
    words = shlex.split(map_provenance["command"])
    at = next(i for i in range(len(words) - 1) if words[i:i + 2] == ["--set", map_provenance["overrides"][-1]])
    del words[at:at + 2]
    return shlex.join([*words[:3], "--maps", ",".join(maps), *words[3:]])


NO_SUCCESS = "n/a: no episode succeeded"


def _pct(rate: float) -> str:
    return f"{100 * rate:.1f} %"


def _number(value: float | None, decimals: int = 1) -> str:
    return "-" if value is None else f"{value:.{decimals}f}"


def format_maps_table(rows: Sequence[dict], title: str) -> str:
    """The suite as a Markdown table: one row per map; the baseline's columns where it played, each of
    :data:`SUITE_COLUMNS` where the drones counted it on some map."""
    base = next((r["baseline"]["name"] for r in rows if "baseline" in r), None)
    counted = [c for c in SUITE_COLUMNS if any(c.name in r["policy"] for r in rows)]
    who = [("policy", "policy"), *([("baseline", base)] if base else [])]
    headers = ["Map", "Cells"]
    for _, label in who:
        headers += [f"{label} success", f"{label} median TTE (steps)"]
    for c in counted:
        headers += [f"{label} {c.label.lower()} (mean)" for _, label in who]
    if base:
        headers.append(f"TTE ratio (policy / {base})")
    lines = [f"# {title}", "", "| " + " | ".join(headers) + " |",
             "|" + "|".join(["---"] + ["---:"] * (len(headers) - 1)) + "|"]
    for r in rows:
        cells = [r["map"], f"{r['cells']:,} ({r['rows']} x {r['cols']})"]
        for key, _ in who:
            cells += [_pct(r[key]["success_rate"]), _number(r[key]["tte_median"])] if key in r else ["-", "-"]
        for c in counted:
            cells += [_number(r.get(key, {}).get(c.name), 2) for key, _ in who]
        if base:
            cells.append(r.get("tte_median_ratio_note") or _number(r.get("tte_median_ratio"), 2))
        lines.append("| " + " | ".join(cells) + " |")
    notes = [f"- {r['map']}: {n}" for r in rows for n in r.get("notes", ())]
    return "\n".join(lines + (["", "Notes:", *notes] if notes else []))


def write_suite_summary(rows: Sequence[dict], out_dir: Path, title: str, provenance: dict) -> str:
    """``maps.md`` and ``maps.json`` (rows and provenance) in ``out_dir``, each written atomically; returns the
    Markdown table."""
    table = format_maps_table(rows, title)
    payload = {"title": title, "maps": list(rows), "provenance": provenance}
    for name, text in (("maps.md", table + "\n"), ("maps.json", json.dumps(payload, indent=2) + "\n")):
        with writing("the map suite summary", out_dir / name):
            write_atomic(out_dir / name, text.encode())
    return table


def _say(line: str) -> None:
    tqdm.write(line)


def evaluate_maps(target: str | Path, maps: Sequence[str], episodes: int = 200, seed: int = 0,
                  num_envs: int | None = None, out_dir: Path | None = None, which: str = "best",
                  progress_bar: bool = True, overrides: Sequence[str] = (), baseline: str | None = None,
                  replace: bool = False, on_map: Callable[[str, dict], None] | None = None) -> dict:
    """Evaluate ``target`` on each of ``maps`` (bundled names or GeoTIFF paths) as ``roshan eval`` with
    ``--set map.name=MAP`` does, each into ``out_dir/<map>/``, then write ``maps.md`` and ``maps.json`` there.

    Every map is checked first (:func:`check_maps`), and without ``replace`` a folder holding results is refused
    (:func:`refuse_held_suite`), both before any episode runs. ``on_map(name, summary)`` is called as each map's
    evaluation ends. Returns ``{"rows", "table", "out_dir"}``."""
    trained, checkpoint = run_config(target, which)
    lands = check_maps(maps, trained, overrides)
    run_dir = checkpoint.parent.parent if checkpoint.parent.name == "checkpoints" else checkpoint.parent
    out = Path(out_dir) if out_dir is not None else suite_folder(run_dir, checkpoint, trained, maps, seed, episodes,
                                                                 num_envs, overrides, baseline)
    if not replace:
        refuse_held_suite(out, list(lands))
    rows, provenance = [], {}
    with output_lock(out):  # a second suite into this folder is refused; each map's evaluation locks its own
        for i, ((name, land), spec) in enumerate(zip(lands.items(), maps, strict=True)):
            if progress_bar:
                _say(f"map {i + 1}/{len(maps)}: {name} ({land.rows} x {land.cols} cells)")
            summary = evaluate_run(target, episodes=episodes, seed=seed, num_envs=num_envs, out_dir=out / name,
                                   which=which, progress_bar=progress_bar,
                                   overrides=[*overrides, _map_override(spec)], baseline=baseline, replace=replace)
            rows.append(map_row(name, land, summary))
            provenance = summary["provenance"]
            if on_map is not None:
                on_map(name, summary)
        suite_provenance = {**provenance, "command": suite_command(provenance, maps), "maps": list(maps),
                            "overrides": list(overrides)}
        title = (f"{run_dir.name} ({checkpoint.stem}) on {len(maps)} map{'s' * (len(maps) != 1)}, {episodes} "
                 f"episode{'s' * (episodes != 1)} per map, seed {seed}")
        table = write_suite_summary(rows, out, title, suite_provenance)
    return {"rows": rows, "table": table, "out_dir": str(out)}
