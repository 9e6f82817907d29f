"""An experiment spec: conditions x seeds, each a training run (or a scripted controller) plus an evaluation.

A spec is a YAML file::

    name: thesis                       # the experiment's folder and study name
    seeds: 3                           # default seeds per condition: a count (0..n-1) or a list
    eval: {episodes: 200, seed: 0}     # default evaluation: episodes, env seed, envs (default: the config's)
    conditions:
      E1_ppo:
        config: configs/fly_simple.yaml          # relative to the spec's folder, or to the working directory
        seeds: 10
        set: {train.total_steps: 270336}         # --set overrides (a mapping or a list of "key=value")
        thesis_set: {train.total_steps: 1080000} # replaces `set`'s values with ``--budget thesis``
        thesis: {success: 91.15 ± 17.46 (100.0), timeout: 8.65 ± 17.31 (0.0)}   # the thesis's row, for the report
      greedy:
        config: configs/thesis/planner.yaml
        controller: greedy                       # no training: the heuristic plays the evaluation episodes
      E7_iql:
        config: configs/iql_offline.yaml
        buffer: {model: models/fly_collision, transitions: 200000}   # recorded once, shared by the seeds
      E1_ppo_long:
        base: E1_ppo                             # E1_ppo's keys (not its note); `set`, `thesis_set` and `eval`
        set: {train.total_steps: 540672}         # merged key by key, this condition's values winning
    departures:                                  # settings kept unlike the thesis, in the report's header
      - {what: ..., why: ..., effect: ...}
    findings:                                    # the thesis's claims, judged in the report (findings.py)
      - claim: a longer run succeeds more often
        source: Table 5.1
        holds: [E1_ppo_long.success > E1_ppo.success]

Expanded, every (condition, seed) is one run, keyed ``<condition>/seed_<s>``; its config is the condition's with
``sim.seed`` = s. A condition's evaluation plays the same episodes for every seed (the env seed is the spec's).
Runs are queued in the spec's order (conditions, then seeds), so list what matters most first. A spec may grow
(new conditions or seeds join a running experiment); a run whose settings changed under its key is refused.
"""

from __future__ import annotations

import fnmatch
import functools
import hashlib
import json
import re
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import yaml

from roshan.algos.frozen import fly_model_path
from roshan.checkpoints import resolve_checkpoint
from roshan.config import Config, apply_overrides, load_config
from roshan.config.profiles import profile_values
from roshan.config.schema import to_dict, values_of_record
from roshan.experiment.findings import Finding, parse_findings

CONTROLLERS = ("policy", "greedy")
BUDGETS = ("local", "thesis")
THESIS_METRICS = ("success", "collision", "boundary", "timeout", "burnout", "tte")
_THESIS_VALUE = re.compile(r"^\s*([-+\d.]+)\s*(?:(?:±|\+-|\+/-)\s*([\d.]+))?\s*(?:\(\s*([-+\d.]+)\s*\))?\s*$")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


class SpecError(ValueError):
    """A spec that cannot be run: the message names the file, the condition and the key."""


@dataclass(frozen=True)
class Reference:
    """One thesis figure: mean, std (over seeds) and median; std / median may be unknown (None)."""

    mean: float
    std: float | None = None
    median: float | None = None

    def __str__(self) -> str:
        s = f"{self.mean:g}"
        if self.std is not None:
            s += f" ± {self.std:g}"
        return s + (f" ({self.median:g})" if self.median is not None else "")


@dataclass(frozen=True)
class Departure:
    """A setting the spec keeps unlike the thesis: what it is, why it is kept and what it does to the figures."""

    what: str
    why: str
    effect: str


@dataclass(frozen=True)
class Buffer:
    """A replay buffer recorded from a frozen policy before the condition's runs train on it (offline RL)."""

    model: str
    transitions: int
    seed: int = 0


@dataclass(frozen=True)
class Condition:
    name: str
    config: str | None  # resolved path, or None for the defaults
    seeds: tuple[int, ...]
    sets: tuple[str, ...] = ()
    controller: str = "policy"
    eval_episodes: int = 200
    eval_seed: int = 0
    eval_envs: int | None = None
    buffer: Buffer | None = None
    thesis: dict[str, Reference] = field(default_factory=dict)
    note: str = ""

    @property
    def trains(self) -> bool:
        return self.controller == "policy"

    def names_key(self, dotted: str) -> bool:
        """Whether the condition's config file, the profiles it names or its ``set`` give ``dotted`` (else the run
        takes the default)."""
        if any(item.split("=", 1)[0].strip() == dotted for item in self.sets):
            return True
        node = self._file_data
        *sections, key = dotted.split(".")
        for s in sections:
            node = node.get(s) if isinstance(node, dict) else None
        return (isinstance(node, dict) and key in node) or dotted in profile_values(self._file_data.get("profile", ""))

    def run_config(self, seed: int, extra: tuple[str, ...] = ()) -> Config:
        """The config of this condition's run with ``seed`` (the condition's overrides, then ``extra``)."""
        return apply_overrides(self._file_config, [*self.sets, *extra, f"sim.seed={seed}"])

    # Read once per condition (a spec is loaded anew for each command): fingerprinting the thesis spec resolves
    # every run's config, ten seeds and a dozen keys of record per condition.
    @cached_property
    def _file_data(self) -> dict:
        return (yaml.safe_load(Path(self.config).read_text()) or {}) if self.config else {}

    @cached_property
    def _file_config(self) -> Config:
        return load_config(self.config)


@dataclass(frozen=True)
class Run:
    condition: Condition
    seed: int

    @property
    def key(self) -> str:
        return f"{self.condition.name}/seed_{self.seed}"

    def fingerprint(self) -> str:
        """A hash of what decides the run: its config's values that differ from the defaults (so a config key added
        later with a default does not make every stored run look changed), controller, evaluation and buffer."""
        c = self.condition
        values = to_dict(c.run_config(self.seed))
        del values["profile"]  # the values it resolved to decide the run, not its name
        for dotted, then in DEFAULTS_OF_RECORD.items():  # a key left to its default: fingerprinted as it was then
            if not c.names_key(dotted):
                _set_dotted(values, dotted, then)
        body = [_non_defaults(values, defaults_of_record()), c.controller,
                c.eval_episodes, c.eval_seed, c.eval_envs, c.buffer and vars(c.buffer)]
        changed = {k: digest for k, (target, digest) in self.models().items()
                   if MODELS_OF_RECORD.get(target) != digest}
        if changed:  # only then: a run whose models are those of record keeps the fingerprint it was stored with
            body.append(changed)
        return hashlib.sha256(json.dumps(body, sort_keys=True, default=str).encode()).hexdigest()[:16]

    def models(self) -> dict[str, tuple[str, str]]:
        """The trained models the run depends on without training them: config key (or ``buffer.model``) ->
        (the setting, :func:`model_digest` of the checkpoint it loads): the level's frozen models (a FlyAgent has none;
        a planner, trained or scripted, flies ``planner.fly_model`` and ``planner.explorer_model``), and an offline
        condition's buffer as ``buffer.model``."""
        c = self.condition
        cfg = c.run_config(self.seed)
        targets = {key: getattr(cfg.planner, key.split(".", 1)[1]) for key in cfg.train.level.frozen_models}
        if c.buffer is not None:
            targets["buffer.model"] = c.buffer.model
        try:
            return {key: (target, model_digest(target, key)) for key, target in targets.items()}
        except FileNotFoundError as e:
            raise SpecError(f"condition {c.name}: {e}") from None


@dataclass(frozen=True)
class Spec:
    name: str
    path: str
    budget: str
    conditions: tuple[Condition, ...]
    storage: str | None = None  # where its runs are recorded unless --storage says otherwise
    findings: tuple[Finding, ...] = ()  # the thesis's claims, judged in the report
    departures: tuple[Departure, ...] = ()  # what the spec keeps unlike the thesis, listed in the report's header

    def runs(self, only: tuple[str, ...] = ()) -> list[Run]:
        """Every (condition, seed), in the spec's order: conditions first, then seeds."""
        return [Run(c, s) for c in self.conditions if not only or c.name in only for s in c.seeds]

    def select(self, patterns: tuple[str, ...], option: str = "--only") -> tuple[str, ...]:
        """The names of the conditions that match any of ``patterns`` (names or shell patterns such as ``E2_*``),
        in the spec's order; () for no patterns (every condition). A pattern that matches nothing is an error."""
        names = [c.name for c in self.conditions]
        for p in patterns:
            if not fnmatch.filter(names, p):
                raise SpecError(f"{self.path}: {option} {p!r} matches no condition; it has {', '.join(names)}")
        return tuple(n for n in names if any(fnmatch.fnmatchcase(n, p) for p in patterns))

    def select_runs(self, patterns: tuple[str, ...], option: str = "--rerun") -> tuple[str, ...]:
        """The keys of the runs that ``patterns`` name, in the spec's order: a condition (name or shell pattern: all
        its seeds) or runs (``CONDITION/seed_S``, patterns too, such as ``E5*/seed_[012]``). A pattern that matches
        nothing is an error."""
        runs = self.runs()
        chosen = set()
        for p in patterns:
            hit = {r.key for r in runs if fnmatch.fnmatchcase(r.condition.name, p) or fnmatch.fnmatchcase(r.key, p)}
            if not hit:
                raise SpecError(f"{self.path}: {option} {p!r} matches no condition or run (CONDITION/seed_S); it has "
                                f"{', '.join(c.name for c in self.conditions)}")
            chosen |= hit
        return tuple(r.key for r in runs if r.key in chosen)

    def condition(self, name: str) -> Condition:
        for c in self.conditions:
            if c.name == name:
                return c
        raise SpecError(f"{self.path}: no condition {name!r}; it has {', '.join(c.name for c in self.conditions)}")

    def fingerprints(self) -> dict[str, str]:
        """run key -> what decides that run (its resolved config, controller, evaluation, buffer): a stored run
        with another fingerprint is another run, and continuing it under this key is refused."""
        return {r.key: r.fingerprint() for r in self.runs()}


# Defaults that changed after runs were recorded, with the value they had then (a field's ``was=``). A run that
# leaves such a key to its default is fingerprinted with the value of record, and every run's config is compared
# with these: so a changed default neither makes a stored run look changed (every FlyAgent run holds a planner
# section) nor hides a real difference (a run that set the new default's value explicitly was already non-default
# then). The one case it cannot tell apart: a condition that relies on the default and ran both before and after the
# change; give such a condition the key explicitly (configs/thesis/planner.yaml sets planner.greedy_home,
# configs/endurance.yaml the return rule's reserve and the final approach).
DEFAULTS_OF_RECORD = values_of_record(Config)

# The models the stored runs loaded, by the digest of the checkpoint file each setting resolved to when runs began to
# be fingerprinted by their models' contents: a run that loads one of these (the same setting, the same bytes)
# keeps the fingerprint it was stored with; another file, or any change to one of these, enters the fingerprint.
MODELS_OF_RECORD = {"models/fly_collision": "bb16fb1903bc60f3", "models/fly_simple": "354955b36c3390f9"}


def model_digest(target: str, key: str = "planner.fly_model") -> str:
    """The first 16 hex digits of the SHA-256 of the checkpoint file that ``target`` (a run folder or checkpoint,
    as ``key`` names it) loads for acting."""
    path = resolve_checkpoint(fly_model_path(target, key))
    stat = path.stat()
    return _file_digest(str(path.resolve()), stat.st_size, stat.st_mtime_ns)


@functools.cache
def _file_digest(path: str, size: int, mtime_ns: int) -> str:  # size and mtime: a rewritten file is read again
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:16]


def defaults_of_record() -> dict:
    """Today's config defaults with :data:`DEFAULTS_OF_RECORD` over them."""
    out = to_dict(Config())
    for dotted, then in DEFAULTS_OF_RECORD.items():
        _set_dotted(out, dotted, then)
    return out


def _set_dotted(values: dict, dotted: str, value) -> None:
    *sections, key = dotted.split(".")
    for s in sections:
        values = values[s]
    values[key] = value


def _non_defaults(values: dict, defaults: dict) -> dict:
    out = {}
    for k, v in values.items():
        d = defaults.get(k)
        if isinstance(v, dict) and isinstance(d, dict):
            sub = _non_defaults(v, d)
            if sub:
                out[k] = sub
        elif v != d:
            out[k] = v
    return out


def parse_reference(value: Any, where: str) -> Reference:
    """``91.15 ± 17.46 (100.0)``, ``73`` or ``[mean, std, median]`` -> Reference."""
    if isinstance(value, (int, float)):
        return Reference(float(value))
    if isinstance(value, (list, tuple)) and 1 <= len(value) <= 3:
        nums = [None if v is None else float(v) for v in value] + [None] * (3 - len(value))
        return Reference(*nums)
    m = _THESIS_VALUE.match(str(value))
    if not m:
        raise SpecError(f"{where}: expected 'mean ± std (median)', a number or [mean, std, median], got {value!r}")
    mean, std, median = m.groups()
    return Reference(float(mean), None if std is None else float(std), None if median is None else float(median))


def _sets(value: Any, where: str) -> tuple[str, ...]:
    if value is None:
        return ()
    return tuple(f"{k}={_yaml_scalar(v)}" for k, v in _as_mapping(value, where).items())


def _as_mapping(value: Any, where: str) -> dict:
    """A ``set``-like value (a mapping, or a list of "key=value") as a mapping."""
    if isinstance(value, dict):
        return value
    if isinstance(value, list) and all(isinstance(v, str) and "=" in v for v in value):
        return dict(v.split("=", 1) for v in value)
    raise SpecError(f"{where}: expected a mapping of config keys to values, or a list of 'key=value', got {value!r}")


def _yaml_scalar(v: Any) -> str:
    return json.dumps(v) if isinstance(v, (list, dict)) else str(v).lower() if isinstance(v, bool) else str(v)


def _seeds(value: Any, where: str) -> tuple[int, ...]:
    if isinstance(value, int) and not isinstance(value, bool) and value >= 1:
        return tuple(range(value))
    if isinstance(value, list) and value and all(isinstance(s, int) and s >= 0 for s in value):
        if len(set(value)) != len(value):
            raise SpecError(f"{where}: a seed is listed twice in {value}")
        return tuple(value)
    raise SpecError(f"{where}: expected a number of seeds (>= 1) or a list of seeds (>= 0), got {value!r}")


def _int(value: Any, where: str, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise SpecError(f"{where}: expected an integer >= {lo}, got {value!r}")
    return value


def _resolve(path: str, spec_dir: Path, where: str) -> str:
    """A file named in the spec: relative to the spec's folder if it is there, else to the working directory."""
    for candidate in (spec_dir / path, Path(path)):
        if candidate.is_file() or candidate.is_dir():
            return str(candidate)
    raise SpecError(f"{where}: {path} not found (looked in {spec_dir} and {Path.cwd()})")


_CONDITION_KEYS = {"config", "seeds", "set", "thesis_set", "controller", "eval", "buffer", "thesis", "note"}
_EVAL_KEYS = {"episodes", "seed", "envs"}
_MERGED_KEYS = ("set", "thesis_set", "eval")  # mappings a condition with a `base` merges key by key


def _inherit(name: str, raw: Any, earlier: dict[str, dict], where: str) -> Any:
    """A condition with ``base: OTHER`` is OTHER's mapping (as OTHER itself expanded, so bases chain) with this
    condition's keys over it: ``set``, ``thesis_set`` and ``eval`` merged key by key, any other key replaced.
    OTHER's note is not inherited (it describes OTHER). OTHER must be listed before this condition."""
    if not isinstance(raw, dict) or "base" not in raw:
        return raw
    at = f"{where}: conditions.{name}.base"
    base = raw["base"]
    if base not in earlier:
        listed = ", ".join(earlier) or "none"
        raise SpecError(f"{at}: expected a condition listed before this one, got {base!r} (listed before: {listed})")
    merged = {k: v for k, v in earlier[base].items() if k != "note"}
    for key, value in raw.items():
        if key == "base":
            continue
        if key in _MERGED_KEYS and value is not None and merged.get(key) is not None:
            where_key = f"{where}: conditions.{name}.{key}"
            merged[key] = {**_as_mapping(merged[key], where_key), **_as_mapping(value, where_key)}
        else:
            merged[key] = value
    return merged


def _condition(name: str, raw: Any, defaults: dict, spec_dir: Path, budget: str, where: str) -> Condition:
    at = f"{where}: conditions.{name}"
    if not _NAME.match(name):
        raise SpecError(f"{at}: a condition name may hold letters, digits, '_', '-' and '.' only")
    if not isinstance(raw, dict):
        raise SpecError(f"{at}: expected a mapping (config, seeds, set, ...), got {raw!r}")
    unknown = set(raw) - _CONDITION_KEYS
    if unknown:
        expected = ", ".join(sorted(_CONDITION_KEYS | {"base"}))
        raise SpecError(f"{at}: unknown key(s) {', '.join(sorted(unknown))}; expected {expected}")
    controller = raw.get("controller", "policy")
    if controller not in CONTROLLERS:
        raise SpecError(f"{at}.controller: expected one of {', '.join(CONTROLLERS)}, got {controller!r}")
    config = _resolve(str(raw["config"]), spec_dir, f"{at}.config") if raw.get("config") else None
    sets = _sets(raw.get("set"), f"{at}.set")
    if budget == "thesis":
        sets += _sets(raw.get("thesis_set"), f"{at}.thesis_set")
    ev = {**defaults["eval"], **(raw.get("eval") or {})}
    unknown = set(ev) - _EVAL_KEYS
    if unknown:
        raise SpecError(f"{at}.eval: unknown key(s) {', '.join(sorted(unknown))}; expected episodes, seed, envs")
    buffer = None
    if raw.get("buffer") is not None:
        b = raw["buffer"]
        if not isinstance(b, dict) or set(b) - {"model", "transitions", "seed"} or "model" not in b:
            raise SpecError(f"{at}.buffer: expected {{model: RUN, transitions: N, seed: S}}, got {b!r}")
        buffer = Buffer(_resolve(str(b["model"]), spec_dir, f"{at}.buffer.model"),
                        _int(b.get("transitions", 200_000), f"{at}.buffer.transitions", 1),
                        _int(b.get("seed", 0), f"{at}.buffer.seed", 0))
    thesis = {}
    for metric, value in (raw.get("thesis") or {}).items():
        if metric not in THESIS_METRICS:
            raise SpecError(f"{at}.thesis: unknown metric {metric!r}; expected {', '.join(THESIS_METRICS)}")
        thesis[metric] = parse_reference(value, f"{at}.thesis.{metric}")
    seeds = _seeds(raw.get("seeds", defaults["seeds"]), f"{at}.seeds")
    episodes = _int(ev.get("episodes", 200), f"{at}.eval.episodes", 1)
    eval_seed = _int(ev.get("seed", 0), f"{at}.eval.seed", 0)
    envs = None if ev.get("envs") is None else _int(ev["envs"], f"{at}.eval.envs", 1)
    cond = Condition(name, config, seeds, sets, controller, episodes, eval_seed, envs, buffer, thesis,
                     str(raw.get("note", "")))
    try:  # a bad key or value fails now, naming the condition, not in a worker an hour later
        cond.run_config(seeds[0])
    except ValueError as exc:
        raise SpecError(f"{at}: {exc}") from None
    return cond


def load_spec(path: str | Path, budget: str = "local") -> Spec:
    """Read and check a spec file; ``budget`` ``thesis`` applies each condition's ``thesis_set``."""
    path = Path(path)
    if budget not in BUDGETS:
        raise SpecError(f"--budget: expected one of {', '.join(BUDGETS)}, got {budget!r}")
    try:
        raw = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise SpecError(f"{path}: cannot read the experiment spec ({exc.strerror})") from None
    except yaml.YAMLError as exc:
        raise SpecError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(raw, dict) or not isinstance(raw.get("conditions"), dict) or not raw["conditions"]:
        raise SpecError(f"{path}: expected a mapping with a non-empty 'conditions' mapping")
    unknown = set(raw) - {"name", "seeds", "eval", "conditions", "note", "storage", "findings", "departures"}
    if unknown:
        raise SpecError(f"{path}: unknown key(s) {', '.join(sorted(unknown))}; expected name, seeds, eval, storage, "
                        "conditions, findings, departures")
    storage = raw.get("storage")
    if storage is not None and (not isinstance(storage, str) or not storage.strip()):
        raise SpecError(f"{path}: storage: expected a journal file (relative to the working directory) or a URL, "
                        f"got {storage!r}")
    name = str(raw.get("name") or path.stem) + ("" if budget == "local" else "-thesis-budget")
    if not _NAME.match(name):
        raise SpecError(f"{path}: name {name!r} may hold letters, digits, '_', '-' and '.' only")
    defaults = {"seeds": raw.get("seeds", 3), "eval": raw.get("eval") or {}}
    expanded: dict[str, dict] = {}  # each condition's mapping with its base's keys in it, for the ones after it
    conditions = []
    for k, v in raw["conditions"].items():
        expanded[str(k)] = _inherit(str(k), v, expanded, str(path))
        conditions.append(_condition(str(k), expanded[str(k)], defaults, path.parent, budget, str(path)))
    try:
        findings = parse_findings(raw.get("findings"), {c.name for c in conditions}, str(path))
    except ValueError as exc:
        raise SpecError(str(exc)) from None
    departures = parse_departures(raw.get("departures"), str(path))
    return Spec(name, str(path), budget, tuple(conditions), storage, findings, departures)


DEPARTURE_KEYS = ("what", "why", "effect")


def parse_departures(raw: Any, where: str) -> tuple[Departure, ...]:
    """The spec's ``departures``: a list of {what, why, effect}, each a non-empty text."""
    if raw is None:
        return ()
    if not isinstance(raw, list):
        raise SpecError(f"{where}: departures: expected a list of {{what, why, effect}}, got {raw!r}")
    out = []
    for i, item in enumerate(raw):
        if not isinstance(item, dict) or set(item) != set(DEPARTURE_KEYS) or not all(
                isinstance(item[k], str) and item[k].strip() for k in DEPARTURE_KEYS):
            raise SpecError(f"{where}: departures[{i}]: expected what, why and effect, each a text, got {item!r}")
        out.append(Departure(*(" ".join(item[k].split()) for k in DEPARTURE_KEYS)))
    return tuple(out)
