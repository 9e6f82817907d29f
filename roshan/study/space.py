"""Search spaces of a study (docs/model/learning.md §13): which config keys are sampled over which ranges or choices,
read from YAML (``configs/spaces/``) and checked against the config before any trial runs.
"""

from __future__ import annotations

import math
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import optuna
import yaml

from roshan.config import Config, ConfigError, all_keys, from_dict, suggest, to_dict
from roshan.study.errors import StudyError

PARAM_FIELDS = {"float": {"low", "high", "log", "step"}, "int": {"low", "high", "log", "step"},
                "categorical": {"choices"}}


@dataclass(frozen=True)
class Param:
    """One sampled config key: ``float`` / ``int`` in [low, high] (optionally log-uniform or stepped), or
    ``categorical`` over ``choices``."""

    key: str
    type: str
    low: float | None = None
    high: float | None = None
    log: bool = False
    step: float | None = None
    choices: tuple = ()

    def suggest(self, trial: optuna.Trial):
        if self.type == "float":
            return trial.suggest_float(self.key, self.low, self.high, log=self.log, step=self.step)
        if self.type == "int":
            return trial.suggest_int(self.key, int(self.low), int(self.high), log=self.log, step=int(self.step or 1))
        return trial.suggest_categorical(self.key, list(self.choices))

    def spec(self) -> dict:
        if self.type == "categorical":
            return {"type": "categorical", "choices": list(self.choices)}
        out = {"type": self.type, "low": self.low, "high": self.high, "log": self.log}
        return out if self.step is None else {**out, "step": self.step}


@dataclass(frozen=True)
class SearchSpace:
    """The sampled keys plus ``tie``: keys that copy a sampled key's value (the reference copies the sampled
    BoundaryTerminal coefficient into Collision)."""

    params: tuple[Param, ...]
    tie: tuple[tuple[str, str], ...] = ()  # (copied key, sampled key)

    def sample(self, trial: optuna.Trial) -> dict[str, Any]:
        values = {p.key: p.suggest(trial) for p in self.params}
        return self.with_ties(values)

    def with_ties(self, values: dict[str, Any]) -> dict[str, Any]:
        return {**values, **{dst: values[src] for dst, src in self.tie if src in values}}

    def to_dict(self) -> dict:
        return {"params": {p.key: p.spec() for p in self.params}, "tie": dict(self.tie)}


def load_space(path: str | Path, base: Config) -> SearchSpace:
    """Read and validate a search-space YAML (see ``configs/spaces/``) against the config ``base``."""
    try:
        data = yaml.safe_load(Path(path).read_text())
    except OSError as exc:
        raise StudyError(f"{path}: cannot read search space ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        raise StudyError(f"{path}: not valid YAML ({exc})") from exc
    return parse_space(data, base, where=str(path))


def parse_space(data: Any, base: Config, where: str = "search space") -> SearchSpace:
    """``{"params": {dotted.key: spec, ...}, "tie": {dotted.key: sampled.key}}`` -> :class:`SearchSpace`.

    Raises:
        StudyError: unknown keys (with the closest valid one), unknown spec fields, empty or invalid ranges, and
            bounds or choices the config itself rejects.
    """
    if not isinstance(data, dict) or not isinstance(data.get("params"), dict) or not data["params"]:
        raise StudyError(f"{where}: expected a mapping with a non-empty 'params' section "
                         "(dotted.config.key: {type: float, low: .., high: ..}) and optionally 'tie'")
    unknown = set(data) - {"params", "tie"}
    if unknown:
        raise StudyError(f"{where}: unknown section(s) {sorted(unknown)}; expected 'params' and 'tie'")
    params = tuple(_parse_param(key, spec, base, where) for key, spec in data["params"].items())
    tie = data.get("tie") or {}
    if not isinstance(tie, dict):
        raise StudyError(f"{where}: 'tie' must map a config key to a sampled key, got {tie!r}")
    sampled = {p.key: p for p in params}
    for dst, src in tie.items():
        _check_key(dst, f"{where}: tie")
        if src not in sampled:
            raise StudyError(f"{where}: tie {dst}: {src!r} is not one of the sampled keys {sorted(sampled)}")
        if dst in sampled:
            raise StudyError(f"{where}: tie {dst}: this key is sampled itself; list it in 'params' or 'tie', not both")
        _check_values(base, dst, _probe_values(sampled[src]), f"{where}: tie {dst} (copies {src})")
    return SearchSpace(params, tuple(tie.items()))


def _parse_param(key: str, spec: Any, base: Config, where: str) -> Param:
    _check_key(key, where)
    at = f"{where}: {key}"
    if not isinstance(spec, dict) or spec.get("type") not in PARAM_FIELDS:
        raise StudyError(f"{at}: expected {{type: float|int|categorical, ...}}, got {spec!r}")
    kind = spec["type"]
    extra = set(spec) - PARAM_FIELDS[kind] - {"type"}
    if extra:
        raise StudyError(f"{at}: unknown field(s) {sorted(extra)} for type {kind}; "
                         f"expected {sorted(PARAM_FIELDS[kind])}")
    _check_field_type(key, kind, at)
    if kind == "categorical":
        choices = spec.get("choices")
        if not isinstance(choices, list) or not choices:
            raise StudyError(f"{at}: 'choices' must be a non-empty list")
        param = Param(key, kind, choices=tuple(choices))
    else:
        param = _parse_range(key, kind, spec, at)
    _check_values(base, key, _probe_values(param), at)
    return param


def _parse_range(key: str, kind: str, spec: dict, at: str) -> Param:
    low, high = _number(spec, "low", at), _number(spec, "high", at)
    step = _number(spec, "step", at) if spec.get("step") is not None else None
    log = spec.get("log", False)
    if not isinstance(log, bool):
        raise StudyError(f"{at}: 'log' must be true or false, got {log!r}")
    if not low < high:
        raise StudyError(f"{at}: empty range [{low}, {high}]; 'low' must be below 'high' "
                         "(to fix a value, use --set instead)")
    if log and low <= 0:
        raise StudyError(f"{at}: a log range needs low > 0, got [{low}, {high}]")
    if step is not None and (step <= 0 or log):
        raise StudyError(f"{at}: 'step' must be > 0 and cannot be combined with log: true")
    if kind == "int" and not all(float(v).is_integer() for v in (low, high, step or 1)):
        raise StudyError(f"{at}: an int range needs whole-number low/high/step, got [{low}, {high}]")
    return Param(key, kind, low=low, high=high, log=log, step=step)


def _number(spec: dict, name: str, at: str) -> float:
    value = spec.get(name)
    try:  # YAML 1.1 reads 1e-3 (no dot) as a string
        if isinstance(value, bool):
            raise ValueError
        out = float(value)
    except (TypeError, ValueError):
        raise StudyError(f"{at}: '{name}' must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise StudyError(f"{at}: '{name}' must be finite, got {value!r}")
    return out


def _check_key(key: str, where: str) -> None:
    if key in all_keys(Config):
        return
    raise StudyError(f"{where}: unknown key {key!r}{suggest(str(key), all_keys(Config))}")


def _leaf_type(key: str) -> type:
    cls: Any = Config
    for part in key.split("."):
        hint = typing.get_type_hints(cls)[part]
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        cls = args[0] if args else hint
    return cls


def _check_field_type(key: str, kind: str, at: str) -> None:
    leaf = _leaf_type(key)
    allowed = {float: ("float", "int", "categorical"), int: ("int", "categorical")}.get(leaf, ("categorical",))
    if kind not in allowed:
        raise StudyError(f"{at}: the config field is {leaf.__name__}; use type {' or '.join(allowed)}")


def _probe_values(p: Param) -> list:
    if p.type == "categorical":
        return list(p.choices)
    return [int(p.low), int(p.high)] if p.type == "int" else [p.low, p.high]


def _check_values(base: Config, key: str, values: list, at: str) -> None:
    """Every bound or choice must be a value the config accepts for ``key``."""
    for v in values:
        try:
            with_values(base, {key: v})
        except ConfigError as exc:
            raise StudyError(f"{at}: {v!r} is not accepted by the config ({exc})") from None


def with_values(cfg: Config, values: dict[str, Any], where: str = "study") -> Config:
    """A validated copy of ``cfg`` with dotted keys set to (already typed) values."""
    data = to_dict(cfg)
    for key, value in values.items():
        node = data
        *parents, leaf = key.split(".")
        for p in parents:
            node = node[p]
        node[leaf] = value
    return from_dict(type(cfg), data, where=where)
