"""How config sections are declared, loaded and validated: ``num``/``choice`` fields, YAML loading, ``--set``
overrides and one validator.

Every section is a frozen dataclass whose defaults are the model's (``docs/model/``). Each field declares its
allowed range in ``metadata`` so one validator checks them all and errors name the key. Sections derive from
:class:`Section`, which runs that validator on construction: a config built in Python (``FlyConfig(frames=0)``)
fails as the same key in a YAML file or ``--set`` would, instead of crashing a kernel later.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import numbers
import types
import typing
from collections.abc import Callable
from dataclasses import MISSING, field
from pathlib import Path
from typing import Any

import yaml

from roshan.io import write_atomic


class ConfigError(ValueError):
    """A config file, key or value is wrong; the message says where and what was expected."""


# The kernels compute in float32 and count in int32: a float beyond float32's range is infinity there, and an int
# beyond int32's wraps. Every float setting must be finite in float32; a setting that ends up in a kernel integer
# declares INT32_MAX (or less) as its upper bound.
FLOAT32_MAX = 3.4028234663852886e38
INT32_MAX = 2**31 - 1


def _range(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False, hi_open: bool = False,
           choices: tuple | None = None, doc: str = "", was=MISSING) -> dict:
    meta = {"lo": lo, "hi": hi, "lo_open": lo_open, "hi_open": hi_open, "choices": choices, "doc": doc}
    if was is not MISSING:
        meta["was"] = was
    return meta


# ``was``: the field's default before it changed (the value of record, :func:`values_of_record`).
def num(default, lo=None, hi=None, *, lo_open=False, hi_open=False, doc="", was=MISSING):
    """A numeric field with an allowed range (closed unless ``*_open``)."""
    return field(default=default, metadata=_range(lo, hi, lo_open=lo_open, hi_open=hi_open, doc=doc, was=was))


def choice(default, choices: tuple, doc="", was=MISSING):
    """A field whose value must be one of ``choices``."""
    return field(default=default, metadata=_range(choices=choices, doc=doc, was=was))


@functools.cache
def values_of_record(cls: type, prefix: str = "") -> dict[str, Any]:
    """Dotted key -> the default it had before it changed (``was=``), for every such field of the tree ``cls``: what
    a run saved before the change did where it left the key to its default or predates it."""
    out = {}
    for f in dataclasses.fields(cls):
        hint = _hints(cls)[f.name]
        if dataclasses.is_dataclass(hint):
            out.update(values_of_record(hint, f"{prefix}{f.name}."))
        elif "was" in (f.metadata or {}):
            out[prefix + f.name] = f.metadata["was"]
    return out


class Section:
    """Base of every config section: validates each field on construction (``Cls(...)``, ``dataclasses.replace``,
    :func:`from_dict`), coercing as YAML loading does (an int for a float field becomes a float).

    Errors read ``Cls: dotted.key = value ...``; the dotted key is known for sections that sit at one place in
    the tree registered with :func:`register_tree` (else the field name alone).
    """

    def __post_init__(self):
        cls = type(self)
        prefix = _PREFIXES.get(cls, "")
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            checked = check_field(f, _hints(cls)[f.name], value, cls.__name__, prefix + f.name)
            if checked is not value:  # frozen: the coerced value (e.g. 3 -> 3.0) replaces the given one
                object.__setattr__(self, f.name, checked)


# Section class -> its dotted prefix in the registered tree ("fly."), for sections found at exactly one place.
_PREFIXES: dict[type, str] = {}


def register_tree(root: type) -> None:
    """Record where each section class of ``root`` sits so construction errors can name the dotted key; a
    class found at several places (``OptimConfig``) keeps the plain field name."""
    places: dict[type, list[str]] = {}

    def walk(cls: type, prefix: str) -> None:
        for f in dataclasses.fields(cls):
            hint = _hints(cls)[f.name]
            if dataclasses.is_dataclass(hint):
                places.setdefault(hint, []).append(f"{prefix}{f.name}.")
                walk(hint, f"{prefix}{f.name}.")

    walk(root, "")
    _PREFIXES.update({cls: where[0] for cls, where in places.items() if len(where) == 1})


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def check_field(f: dataclasses.Field, hint, value, where: str, key: str):
    """The one check of a field's value (type, coercion, range, choices): ``value`` as stored, or ConfigError
    naming ``where`` and ``key``. A nested section must already be an instance of its class."""
    if dataclasses.is_dataclass(hint):
        if not isinstance(value, hint):
            raise ConfigError(f"{where}: {key} must be a {hint.__name__}, got {value!r}")
        return value
    return _check_value(_coerce(_unbool_choice(value, f), hint, where, key), f, where, key)


def _unbool_choice(value, f: dataclasses.Field):
    """YAML 1.1 reads an unquoted ``off`` / ``on`` as false / true: for a field whose choices are the words, give
    the word back (``preset: off`` means the choice "off", not a type error)."""
    choices = f.metadata.get("choices") if f.metadata else None
    if isinstance(value, bool) and choices:
        word = "on" if value else "off"
        if word in choices:
            return word
    return value


# ---------------------------------------------------------------------------------------------- loading


def load_config(path: str | Path | None = None, overrides: list[str] | tuple[str, ...] = (), *, cls: type,
                upgrade: Callable[[dict], dict] | None = None, moved: dict[str, str] | None = None,
                flags: dict[str, tuple[str, Any]] | None = None, base: Callable[[dict], dict] | None = None):
    """Load ``path`` (YAML) into ``cls``, apply ``key.sub=value`` overrides and validate everything; ``upgrade``
    brings the file's dict from an older layout first, and ``moved`` (old dotted key -> new) renames override
    keys of that older layout. ``flags`` (dotted key -> (option, value), e.g. ``{"wind.speed": ("--wind-speed",
    -3.0)}``) are a command's own options for keys; they apply before the overrides. ``base`` then fills in what
    the file, the flags and the overrides leave unset (the profiles the result names).

    Raises:
        ConfigError: naming where the bad value came from (the file, ``--set`` or the option), the key and what
            was expected.
    """
    data: dict = {}
    where = "defaults"
    if path is not None:
        where = str(path)
        try:
            text = Path(path).read_text()
        except OSError as exc:
            raise ConfigError(f"{path}: cannot read config file ({exc.strerror})") from exc
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: not valid YAML ({exc})") from exc
        if data is None:  # an empty (or all-comment) file is a mistake, not a request for every default
            sections = ", ".join(f.name for f in dataclasses.fields(cls)[:4])
            raise ConfigError(f"{path}: the config file is empty; expected sections such as {sections} (to use "
                              "the defaults, give no config file)")
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: expected a mapping of sections at the top level, got {type(data).__name__}")
    if upgrade is not None:
        data = upgrade(data)
    origins: dict[str, str] = {}  # dotted key -> the option that set it last (an error names it, not the file)
    for key, (option, value) in (flags or {}).items():
        _set_key(data, key, value, cls)
        origins[key] = option
    for item in overrides:
        origins[_apply_override(data, item, cls, moved or {})] = "--set"
    if base is not None:
        data = base(data)
    return from_dict(cls, data, where=where, origins=origins)


def apply_overrides(cfg, overrides: list[str] | tuple[str, ...], where: str = "--set",
                    moved: dict[str, str] | None = None):
    """A copy of the config ``cfg`` with ``section.key=value`` overrides applied and validated."""
    data = to_dict(cfg)
    for item in overrides:
        _apply_override(data, item, type(cfg), moved or {})
    return from_dict(type(cfg), data, where=where)


def from_dict(cls: type, data: dict, where: str = "config", prefix: str = "", origins: dict[str, str] | None = None):
    """Build dataclass ``cls`` from a nested dict; unknown keys, wrong types and out-of-range values raise, naming
    ``where`` (or, for a dotted key in ``origins``, the option that set it)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: {prefix or 'top level'} must be a mapping, got {data!r}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    hints = _hints(cls)
    for key in data:
        if key not in fields:
            valid = [prefix + name for name in fields]
            raise ConfigError(f"{where}: unknown key {prefix + str(key)!r}{suggest(prefix + str(key), valid)}")
    kwargs = {}
    for name, value in data.items():
        hint = hints[name]
        full = f"{prefix}{name}"
        if dataclasses.is_dataclass(hint):
            kwargs[name] = from_dict(hint, value if value is not None else {}, where, full + ".", origins)
        else:  # checked here to name the file; the section's own check then finds nothing more
            kwargs[name] = check_field(fields[name], hint, value, (origins or {}).get(full, where), full)
    return cls(**kwargs)


def to_dict(cfg) -> dict:
    """A plain nested dict of a config (for YAML/JSON output)."""
    return dataclasses.asdict(cfg)


def dump_config(cfg, path: str | Path) -> None:
    """Write the resolved config as YAML, atomically: a full disk or a kill leaves the old file whole, never an
    empty one."""
    write_atomic(path, yaml.safe_dump(to_dict(cfg), sort_keys=False).encode())


def replace(cfg, **changes):
    """``dataclasses.replace`` that re-validates the changed fields."""
    return from_dict(type(cfg), {**to_dict(cfg), **changes}, where="replace")


def all_keys(cls: type, prefix: str = "") -> list[str]:
    """Every dotted key of a config class (for help texts and suggestions)."""
    return list(_keys(cls, prefix))


@functools.cache
def _keys(cls: type, prefix: str = "") -> tuple[str, ...]:
    """:func:`all_keys`, once per class: an override checks its key against them (the experiment spec resolves
    hundreds of runs, each with several overrides, and the type hints behind them cost ~0.03 s a lookup)."""
    keys = []
    for f in dataclasses.fields(cls):
        hint = _hints(cls)[f.name]
        if dataclasses.is_dataclass(hint):
            keys += _keys(hint, f"{prefix}{f.name}.")
        else:
            keys.append(prefix + f.name)
    return tuple(keys)


@functools.cache
def _key_set(cls: type) -> frozenset[str]:
    return frozenset(_keys(cls))


def _apply_override(data: dict, item: str, cls: type, moved: dict[str, str]) -> str:
    """Apply ``--set`` ``item`` to ``data``; the dotted key it set."""
    if "=" not in item:
        raise ConfigError(f"--set {item!r}: expected section.key=value")
    dotted, raw = item.split("=", 1)
    dotted = moved.get(dotted.strip(), dotted.strip())
    if dotted not in _key_set(cls):
        raise ConfigError(f"--set: unknown key {dotted.strip()!r}{suggest(dotted.strip(), all_keys(cls))}")
    try:
        value = yaml.safe_load(raw)
    except yaml.YAMLError as exc:
        raise ConfigError(f"--set {item!r}: cannot parse value ({exc})") from exc
    _set_key(data, dotted, value, cls, f"--set {item!r}")
    return dotted


def _set_key(data: dict, dotted: str, value: Any, cls: type, where: str = "") -> None:
    if dotted not in _key_set(cls):
        raise ConfigError(f"{where or dotted}: unknown key {dotted!r}{suggest(dotted, all_keys(cls))}")
    parts = dotted.split(".")
    node = data
    for p in parts[:-1]:
        node = node.setdefault(p, {})
        if not isinstance(node, dict):
            raise ConfigError(f"{where or dotted}: {p!r} is not a section")
    node[parts[-1]] = value


# Names other RL libraries (Stable-Baselines3, CleanRL) use for our keys: string similarity alone would answer
# "learning_rate" with "decay_rate" rather than "lr".
ALIASES = {"learning_rate": "lr", "n_epochs": "k_epochs", "epochs": "k_epochs", "update_epochs": "k_epochs",
           "gae_lambda": "lam", "clip_range": "eps_clip", "clip_coef": "eps_clip", "ent_coef": "entropy_coeff",
           "vf_coef": "value_loss_coef", "n_steps": "horizon", "num_steps": "horizon", "num_envs": "envs",
           "n_envs": "envs", "discount": "gamma", "target_kl": "kl_target"}


def suggest(key: str, valid) -> str:
    """"; did you mean 'x'?" for the valid key closest to ``key`` (a known alias first), else the valid keys."""
    head, _, last = key.rpartition(".")
    alias = f"{head}.{ALIASES[last]}" if head and last in ALIASES else ALIASES.get(last, "")
    if alias in valid:
        return f"; did you mean {alias!r}?"
    close = difflib.get_close_matches(key, list(valid), n=1, cutoff=0.5)
    if not close and "." in key:
        close = difflib.get_close_matches(key.split(".")[-1], [v.split(".")[-1] for v in valid], n=1, cutoff=0.5)
    return f"; did you mean {close[0]!r}?" if close else f"; valid keys: {', '.join(sorted(valid))}"


def _as_float(value: Any) -> float | None:
    """A number, or a string like "3e-5" (YAML 1.1 reads an exponent without a dot as a string); else None."""
    if isinstance(value, numbers.Real) and not isinstance(value, bool):  # numpy numbers too (Python callers)
        return float(value)
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return None
    return None


def _as_int(value: Any) -> int | None:
    """An int, a numpy int (Python callers), a whole float like 4.0 or a string of one like "3e9" (YAML 1.1 reads
    an exponent without a dot as a string); else None (bools are not numbers here)."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        return value
    if isinstance(value, str):
        number = _as_float(value)
        return int(number) if number is not None and number.is_integer() else None
    if isinstance(value, numbers.Integral) or (isinstance(value, numbers.Real) and float(value).is_integer()):
        return int(value)
    return None


def _coerce(value: Any, hint, where: str, key: str):
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if value is None:
            return None
        hint = args[0]
    if hint is bool:
        if isinstance(value, bool):
            return value
    elif hint is int:
        number = _as_int(value)
        if number is not None:
            return number
    elif hint is float:
        number = _as_float(value)
        if number is not None:
            return number
    elif hint is str:
        if isinstance(value, str):
            return value
    else:
        return value
    raise ConfigError(f"{where}: {key} must be {hint.__name__}, got {value!r}")


def _check_value(value, f: dataclasses.Field, where: str, key: str):
    meta = f.metadata
    if isinstance(value, float):
        _check_finite(value, meta, where, key)
    if not meta or value is None:
        return value
    if meta.get("choices") is not None and value not in meta["choices"]:
        raise ConfigError(f"{where}: {key} = {value!r}; expected one of {', '.join(map(str, meta['choices']))}")
    lo, hi = meta.get("lo"), meta.get("hi")
    too_low = lo is not None and (value <= lo if meta["lo_open"] else value < lo)
    too_high = hi is not None and (value >= hi if meta["hi_open"] else value > hi)
    if too_low or too_high:
        raise ConfigError(f"{where}: {key} = {value!r} is out of range; expected {_range_text(meta)}"
                          + (f" ({meta['doc']})" if meta.get("doc") else ""))
    return value


def _check_finite(value: float, meta, where: str, key: str) -> None:
    """Refuse NaN, infinities and floats that float32 (what the kernels compute in) turns into infinities: a range
    check alone lets ``inf`` through every bound of the form ``> 0``."""
    if abs(value) <= FLOAT32_MAX:
        return
    ranged = meta and (meta.get("lo") is not None or meta.get("hi") is not None)
    expected = f"expected {_range_text(meta)}" if ranged else "expected a finite number"
    if value != value:  # NaN compares false with everything
        raise ConfigError(f"{where}: {key} is NaN; {expected}")
    if math.isinf(value):
        raise ConfigError(f"{where}: {key} = {value!r} is infinite; {expected}")
    raise ConfigError(f"{where}: {key} = {value!r} is beyond float32's range (what the kernels compute in, "
                      f"up to 3.4e38); {expected}")


def _range_text(meta: dict) -> str:
    lo, hi = meta["lo"], meta["hi"]
    left = "(" if meta["lo_open"] else "["
    right = ")" if meta["hi_open"] else "]"
    if hi is None:
        return f"{'>' if meta['lo_open'] else '>='} {lo}"
    if lo is None:
        return f"{'<' if meta['hi_open'] else '<='} {hi}"
    return f"a value in {left}{lo}, {hi}{right}"
