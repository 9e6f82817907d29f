"""The experiment's tables, the way the thesis reports them: per condition, each rate as mean ± std (median) over
seeds (every seed's rate taken over its evaluation episodes), beside the thesis's row; TTE as mean ± std (median)
over all evaluation episodes of all seeds (the thesis's planner tables); one row per seed too.

The std is the population std over seeds (numpy's default, ddof = 0): the thesis's figures imply it (E1 PPO's
boundary exits, 0.20 ± 0.40 over 10 seeds of 200 episodes, fit only two seeds at 1 % and ddof = 0).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from roshan import reproducible
from roshan.experiment.findings import findings_markdown
from roshan.experiment.runner import (
    STUDY_ATTR,
    check_runs,
    experiment_dir,
    load_experiment,
    progress,
    results_of,
    spec_storage,
)
from roshan.experiment.spec import Condition, Reference, Run, Spec, load_spec
from roshan.io import OutputError, write_atomic, writing
from roshan.study.storage import open_storage

RATES = ("success", "collision", "boundary", "timeout", "burnout")


def seed_stats(values) -> Reference:
    """mean ± std (median) over seeds; std with ddof = 0 (see the module docstring)."""
    v = np.asarray(values, dtype=float)
    return Reference(float(v.mean()), float(v.std()), float(np.median(v)))


def rate(result: dict, metric: str) -> float:
    """A run's rate in percent: success, or the share of episodes that failed by ``metric``."""
    if metric == "success":
        return 100.0 * result["success_rate"]
    return 100.0 * result["failure_rates"].get(metric, 0.0)


def done_results(spec: Spec, results: dict[str, dict], cond: Condition) -> list[dict]:
    """The finished runs' results of one condition, in seed order."""
    return [results[r.key] for r in spec.runs((cond.name,)) if r.key in results]


def _figures(done: list[dict]) -> dict:
    """Each rate's seed statistics and TTE over all episodes of the seeds' results (any weights' results)."""
    out = {m: seed_stats([rate(r, m) for r in done]) for m in RATES}
    tte = [t for r in done for t in r.get("tte_episodes", [])]
    out["tte"] = seed_stats(tte) if tte and all("tte_episodes" in r for r in done) else None
    return out


def condition_rows(spec: Spec, results: dict[str, dict]) -> list[dict]:
    """One aggregate per condition: seeds done of planned, each rate's seed statistics, TTE over episodes (best
    weights), the same figures with the last and the training-objective weights over the seeds that have them
    (``last_seeds``, ``objective_seeds``), and the code commits the seeds ran."""
    rows = []
    for cond in spec.conditions:
        done = done_results(spec, results, cond)
        row = {"condition": cond.name, "seeds": len(done), "planned": len(cond.seeds), "thesis": cond.thesis}
        if done:
            row.update(_figures(done))
            for key in ("last", "objective"):
                have = [r[key] for r in done if key in r]
                if cond.trains and have:  # runs made before a set of weights was evaluated have none
                    row[key] = _figures(have)
                    row[f"{key}_seeds"] = len(have)
            row["commits"] = commits(done)
            row["machines"] = machines(done)
            row["minutes"] = float(sum(r.get("minutes", 0.0) for r in done))
            row["episodes"] = int(sum(r["episodes"] for r in done))
        rows.append(row)
    return rows


def commits(done: list[dict]) -> list[str]:
    """The short commits of the code that made the results ('+' marks uncommitted changes, '?' an unknown one)."""
    out = []
    for r in done:
        code = r.get("code") or {}
        c = (code.get("commit") or "?")[:7] + ("+" if code.get("dirty") else "")
        if c not in out:
            out.append(c)
    return out


def made_on(result: dict) -> list[str]:
    """The machines that trained and evaluated a run, in order ('?' for a run finished before results recorded
    them: those recorded only the host name)."""
    out: list[str] = []
    for m in [*result.get("trained_on", []), *([result["machine"]] if "machine" in result else [])]:
        label = reproducible.label(m)
        if label not in out:
            out.append(label)
    return out or ["?"]


def machines(done: list[dict]) -> list[str]:
    """The machines that made a row's seeds."""
    out: list[str] = []
    for r in done:
        out += [m for m in made_on(r) if m not in out]
    return out


def _cell(ref: Reference | None, digits: int = 1) -> str:
    if ref is None:
        return "-"
    return f"{ref.mean:.{digits}f} ± {ref.std:.{digits}f} ({ref.median:.{digits}f})"


def _weights_cell(row: dict, key: str, metric: str, digits: int) -> str:
    """A metric with the ``key`` weights (last, objective), marked ``[k of n]`` where only k of the row's n seeds
    have them."""
    text = _cell((row.get(key) or {}).get(metric), digits)
    k = row.get(f"{key}_seeds", 0)
    return text if k in (0, row["seeds"]) else f"{text} [{k} of {row['seeds']}]"


def _shown_rates(cond: Condition, row: dict) -> list[str]:
    """The rates worth a column for this condition: measured non-zero, or reported by the thesis."""
    return [m for m in RATES if m == "success" or m in cond.thesis or (m in row and row[m].mean > 0)]


def compute_line(spec: Spec, rows: list[dict]) -> str:
    """The spec's wall-clock on the machines that ran it: the finished runs' minutes (training and evaluation,
    one run per worker), and the runs still to make, estimated at their condition's mean where it has one."""
    done = sum(r.get("minutes", 0.0) for r in rows)
    left = unknown = 0
    est = 0.0
    for row in rows:
        missing = row["planned"] - row["seeds"]
        if missing > 0 and row["seeds"]:
            est += missing * row["minutes"] / row["seeds"]
            left += missing
        elif missing > 0:
            unknown += missing
    return (f"Compute: {sum(r['seeds'] for r in rows)} finished runs took {done / 60:.1f} h (one run per worker, "
            f"summed); the {left} runs still to make of conditions with results take ~{est / 60:.1f} h more at their "
            f"condition's mean" + (f", and {unknown} runs of conditions without any result are not estimated." if
                                  unknown else "."))


def departures_markdown(spec: Spec) -> list[str]:
    """The header's list of what the spec keeps unlike the thesis, each with its reason and measured effect."""
    if not spec.departures:
        return []
    return ["Departures from the thesis kept here:", "",
            *(f"- **{d.what}** Why: {d.why} Effect: {d.effect}" for d in spec.departures), ""]


def _code(row: dict) -> str:
    c = row.get("commits") or []
    return c[0] if len(c) == 1 else f"mixed: {', '.join(c)}"


def markdown(spec: Spec, rows: list[dict], results: dict[str, dict] | None = None) -> str:
    """A table per condition group: ours (best, last and training-objective weights) beside the thesis's, mean ±
    std (median), with the commit of the code that made each row; then the thesis's findings, judged."""
    out = [f"Experiment `{spec.name}` ({spec.path}, budget {spec.budget}). Rates in % of evaluation episodes, "
           "mean ± std (median) over seeds (std: ddof = 0); TTE in low-level steps over all evaluation episodes of "
           "all seeds. *best*: the weights of the best periodic evaluation (selected on other episodes); *last*: "
           "the last weights; *objective*: the best training-objective checkpoint, the thesis's rule ('-': recorded "
           "for no seed; '[k of n]': over the k seeds that have it, runs made before it was evaluated have none). "
           "*code*: the commit each row's seeds ran ('mixed' when they differ, '+' uncommitted changes, '?' a run "
           "finished before results recorded their commit). *machine*: the CPUs that trained and evaluated the seeds, "
           "with the kernels' instruction set where torch ran outside the reproducible mode ('?': a run finished "
           "before results recorded its machine).", "",
           *departures_markdown(spec),
           "| condition | seeds | code | machine | metric | ours: best | last | objective | thesis |",
           "|---|---|---|---|---|---|---|---|---|"]
    for cond, row in zip(spec.conditions, rows, strict=True):
        seeds = f"{row['seeds']}/{row['planned']}"
        if not row["seeds"]:
            out.append(f"| {cond.name} | {seeds} | | | - | not run yet | | | - |")
            continue
        metrics = _shown_rates(cond, row) + (["tte"] if row.get("tte") is not None else [])
        for i, m in enumerate(metrics):
            digits = 0 if m == "tte" else 1
            cells = [_cell(row.get(m), digits)] + [_weights_cell(row, k, m, digits) for k in ("last", "objective")]
            ref = str(cond.thesis[m]) if m in cond.thesis else "-"
            label = "TTE (steps)" if m == "tte" else f"{m} %"
            first = i == 0
            machine = "; ".join(row["machines"]) if first else ""
            out.append(f"| {cond.name if first else ''} | {seeds if first else ''} | {_code(row) if first else ''} "
                       f"| {machine} | {label} | {' | '.join(cells)} | {ref} |")
    out += ["", compute_line(spec, rows)]
    text = "\n".join(out) + "\n"
    if results is not None and spec.findings:
        by_condition = {c.name: done_results(spec, results, c) for c in spec.conditions}
        seeds = {c.name: (row["seeds"], row["planned"]) for c, row in zip(spec.conditions, rows, strict=True)}
        named = {c.condition for f in spec.findings for c in f.checks} | {
            c.other for f in spec.findings for c in f.checks if c.other}
        baselines = {c.name: c.thesis for c in spec.conditions if not c.trains and c.name in named and c.thesis}
        text += findings_markdown(spec.findings, by_condition, seeds, baselines)
    return text


def per_seed_csv(spec: Spec, results: dict[str, dict]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["condition", "seed", "episodes", *[f"{m}_pct" for m in RATES], "tte_mean", "tte_median",
                "last_success_pct", "objective_success_pct", "updates", "env_steps", "train_minutes", "minutes",
                "machine", "commit", "low_level"])
    for run in spec.runs():
        r = results.get(run.key)
        if r is None:
            continue
        tte = r["tte_episodes"]
        train = r.get("train", {})
        w.writerow([run.condition.name, run.seed, r["episodes"], *[f"{rate(r, m):.2f}" for m in RATES],
                    f"{np.mean(tte):.1f}" if tte else "", f"{np.median(tte):.1f}" if tte else "",
                    f"{100 * r['last']['success_rate']:.2f}" if "last" in r else "",
                    f"{100 * r['objective']['success_rate']:.2f}" if "objective" in r else "",
                    train.get("updates", ""), train.get("env_steps", ""),
                    f"{train['seconds'] / 60:.2f}" if "seconds" in train else "", f"{r.get('minutes', 0):.2f}",
                    "; ".join(made_on(r)), commits([r])[0], low_level(run, r)])
    return buf.getvalue()


def low_level(run: Run, result: dict) -> str:
    """The digest of the low-level FlyAgent a run flew (``planner.fly_model``) or recorded its buffer with: '' for
    a run that loads no model, '?' for one finished before results recorded it."""
    if not run.models():
        return ""
    models = result.get("models")
    if models is None:
        return "?"
    key = "planner.fly_model" if "planner.fly_model" in models else "buffer.model"
    return models[key]["digest"] if key in models else ""


def _plain(row: dict) -> dict:
    out = {}
    for k, v in row.items():
        if isinstance(v, Reference):
            out[k] = vars(v)
        elif isinstance(v, dict):
            out[k] = {m: None if ref is None else vars(ref) for m, ref in v.items()}
        else:
            out[k] = v
    return out


def success_figure(spec: Spec, rows: list[dict]):
    """Success per condition, one row each in the spec's order (so a spec of any length stays one page wide):
    ours' mean ± std as a bar with every seed as a dot, the thesis's as an orange square, and "not run" where a
    condition has no result yet."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [c.name for c in spec.conditions]
    fig, ax = plt.subplots(figsize=(10.0, max(2.5, 0.28 * len(names) + 1.4)))
    labels = {"ours": "ours: mean ± std over seeds", "thesis": "thesis"}
    for i, (cond, row) in enumerate(zip(spec.conditions, rows, strict=True)):
        if row["seeds"]:
            s = row["success"]
            ax.barh(i - 0.18, s.mean, 0.36, xerr=s.std, color="tab:blue", alpha=0.7, capsize=2,
                    label=labels.pop("ours", None))
            pts = row.get("_points", [])
            ax.plot(pts, [i - 0.18] * len(pts), "k.", ms=3)
        else:
            ax.text(1, i - 0.18, "not run", va="center", fontsize=7, color="0.4", style="italic")
        ref = cond.thesis.get("success")
        if ref is not None:
            ax.errorbar(ref.mean, i + 0.18, xerr=0 if ref.std is None else ref.std, fmt="s", ms=4,
                        color="tab:orange", capsize=2, label=labels.pop("thesis", None))
    ax.set_yticks(range(len(names)), names, fontsize=8)
    ax.invert_yaxis()  # the spec's first condition on top
    ax.set_xlabel("success (% of evaluation episodes)")
    ax.set_xlim(0, 105)
    ax.set_title(f"{spec.name}: success per condition (dots: seeds)")
    ax.grid(axis="x", alpha=0.3)
    ax.legend(loc="lower right", fontsize=7)
    fig.tight_layout()
    return fig


def plot(spec: Spec, rows: list[dict], path: Path) -> None:
    import matplotlib.pyplot as plt

    fig = success_figure(spec, rows)
    fig.savefig(path, dpi=110)  # 1,100 px wide whatever the number of conditions
    plt.close(fig)


def write_report(spec: Spec, study, out_dir: str | Path) -> list[dict]:
    """report.md, per_seed.csv, summary.json, runs/<condition>/seed_<s>.json and success.png in ``out_dir``."""
    out = Path(out_dir)
    results = results_of(study)
    rows = condition_rows(spec, results)
    for cond, row in zip(spec.conditions, rows, strict=True):
        row["_points"] = [rate(results[r.key], "success") for r in spec.runs((cond.name,)) if r.key in results]
    with writing("the experiment report", out):
        out.mkdir(parents=True, exist_ok=True)
        write_atomic(out / "report.md", markdown(spec, rows, results).encode())
        write_atomic(out / "per_seed.csv", per_seed_csv(spec, results).encode())
        summary = [_plain({k: v for k, v in r.items() if not k.startswith("_")}) for r in rows]
        write_atomic(out / "summary.json", (json.dumps(summary, indent=2) + "\n").encode())
        for key, r in results.items():
            path = out / "runs" / f"{key}.json"
            path.parent.mkdir(parents=True, exist_ok=True)
            write_atomic(path, (json.dumps(r, indent=2) + "\n").encode())
        plot(spec, rows, out / "success.png")
    return rows



REPORT_FILES = ("report.md", "per_seed.csv", "summary.json", "success.png", "runs")


def refuse_foreign_outputs(spec: Spec, out: Path) -> None:
    """Without --replace: a report folder that holds any file of a report's names (an earlier report, an
    evaluation's summary.json, another experiment's report) is refused: OutputError naming them, what they belong
    to, and the two ways out. Nothing is overwritten that the user did not name."""
    held = [name for name in REPORT_FILES if (out / name).exists()]
    if not held:
        return
    try:
        ours = (out / "report.md").read_text().startswith(f"Experiment `{spec.name}` (")
    except (OSError, UnicodeDecodeError):
        ours = False
    what = f"an earlier report of experiment {spec.name!r}" if ours else \
        f"something other than a report of experiment {spec.name!r}"
    raise OutputError("the experiment report", out, f"it holds {', '.join(held)} of {what}; give --replace to "
                                                    "overwrite them, or --out DIR to write a new folder")


def report_experiment(spec_path: str | Path, budget: str, storage: str | None, root: str | Path,
                      out_dir: str | Path | None, replace: bool = False) -> str:
    """``roshan experiment report``: the report of SPEC's finished runs read from its journal (``storage``, else
    the spec's, else ROOT/NAME/experiment.journal), written to ``out_dir`` (default ROOT/NAME/report); returns what
    the command prints: the runs' progress, the tables and the files written. A spec whose conditions changed
    under runs that started is refused as ``experiment run`` refuses it (the old runs would read as the new
    settings'), and so is a folder holding other files (:func:`refuse_foreign_outputs`) unless ``replace``."""
    spec = load_spec(spec_path, budget)
    url = spec_storage(spec, root, storage)
    if "://" not in url and not Path(url).is_file():
        raise FileNotFoundError(f"{url}: no experiment journal; run `roshan experiment run {spec_path}` first "
                                "(or give --storage / --root)")
    # a cut journal is repaired by the command that writes it, naming it: a spec's committed journal is written
    # only when --storage names it
    hint = f"`roshan experiment run {spec_path}{' --budget thesis' if budget != 'local' else ''} --storage {url}`"
    study = load_experiment(open_storage(url, heartbeat=None, repair=False, repair_hint=hint), spec.name)
    check_runs(spec, study.user_attrs[STUDY_ATTR], study)
    out = Path(out_dir) if out_dir else experiment_dir(root, spec.name) / "report"
    if not replace:
        refuse_foreign_outputs(spec, out)
    rows = write_report(spec, study, out)
    p = progress(study, set(spec.fingerprints()))
    return "\n".join([
        f"experiment {spec.name}: {p['done']}/{len(spec.runs())} runs done, {p['running']} running, "
        f"{p['waiting']} waiting" + (f", {p['failed']} failed" if p["failed"] else ""),
        markdown(spec, rows), f"wrote {out}/report.md, per_seed.csv, summary.json, runs/, success.png"])
