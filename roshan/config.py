"""Typed, frozen configuration dataclasses with YAML loading, ``--set`` overrides and validation.

Every section is a frozen dataclass whose defaults are the spec's (``shared/spec/firespin.md``). Each field
declares its allowed range in ``metadata`` so one validator checks them all and errors name the key.
"""

from __future__ import annotations

import dataclasses
import difflib
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml


class ConfigError(ValueError):
    """A config file, key or value is wrong; the message says where and what was expected."""


def _range(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False, hi_open: bool = False,
           choices: tuple | None = None, doc: str = "") -> dict:
    return {"lo": lo, "hi": hi, "lo_open": lo_open, "hi_open": hi_open, "choices": choices, "doc": doc}


def num(default, lo=None, hi=None, *, lo_open=False, hi_open=False, doc=""):
    """A numeric field with an allowed range (closed unless ``*_open``)."""
    return field(default=default, metadata=_range(lo, hi, lo_open=lo_open, hi_open=hi_open, doc=doc))


def choice(default, choices: tuple, doc=""):
    """A field whose value must be one of ``choices``."""
    return field(default=default, metadata=_range(choices=choices, doc=doc))


# ---------------------------------------------------------------------------------------------- sections


@dataclass(frozen=True)
class ConvectionConfig:
    """Convection particles: Langevin SDE for hot gas / embers (firespin.md 7.1)."""

    enabled: bool = True  # emit_convective
    y_st: float = num(1.0, 0.0, lo_open=True, doc="initial intensity")
    y_lim: float = num(0.2, 0.0, lo_open=True, doc="intensity below which a particle dies")
    fl: float = num(0.15, 0.0, doc="position scaling factor F_l")
    c0: float = num(1.98, 0.0, doc="Kolmogorov-like constant C_0")
    tau_mem: float = num(10.0, 0.0, lo_open=True, doc="intensity decay time (s)")
    lt: float = num(80.0, 0.0, lo_open=True, doc="integral length scale L_t (m)")


@dataclass(frozen=True)
class RadiationConfig:
    """Radiation particles: random walk on a slowly growing circle (firespin.md 7.2)."""

    enabled: bool = True  # emit_radiation
    y_st: float = num(1.0, 0.0, lo_open=True, doc="initial intensity")
    y_lim: float = num(0.165, 0.0, lo_open=True, doc="intensity below which a particle dies")


@dataclass(frozen=True)
class FireConfig:
    """The FireSPIN cellular automaton (firespin.md 1-8)."""

    dt: float = num(0.1, 0.0, 10.0, lo_open=True, doc="time step (s)")
    flood_duration: float = num(5.0, 0.0, doc="how long a flooded cell stays flooded (s)")
    uniform_ignition_time: float = num(100.0, 0.0, lo_open=True, doc="tau_ign on the uniform map (s)")
    uniform_burning_time: float = num(120.0, 0.0, lo_open=True, doc="tau_burn on the uniform map (s)")
    convection: ConvectionConfig = field(default_factory=ConvectionConfig)
    radiation: RadiationConfig = field(default_factory=RadiationConfig)
    conv_capacity: int = num(0, 0, doc="convection particles per env; 0 = auto from the map size")
    rad_capacity: int = num(0, 0, doc="radiation particles per env; 0 = auto from the map size")


@dataclass(frozen=True)
class WindConfig:
    """Constant wind per episode (firespin.md 6)."""

    speed: float = num(10.0, 0.0, 100.0, doc="10-m wind speed U_w (m/s)")
    direction: float = num(-1.0, -1.0, 360.0, hi_open=True,
                           doc="degrees from the row axis (south) towards the column axis (east); -1 = random")
    turbulence: float = num(0.314, 0.0, doc="turbulence ratio a (u' = a * U_w)")


@dataclass(frozen=True)
class IgnitionConfig:
    """The initial fire generator (firespin.md 11, newest code)."""

    fire_percentage: float = num(0.015, 0.0, 1.0, doc="fraction of all cells to ignite")
    clusters: int = num(2, 1, doc="number of clusters (or rings)")
    spread_prob: float = num(0.5, 0.0, 1.0, doc="base probability that a cluster grows into a neighbour")
    noise: float = num(1.0, 0.0, 2.0, doc="amplitude of the perturbation of spread_prob")
    pattern: str = choice("cluster", ("cluster", "scattered", "ring", "random"))


@dataclass(frozen=True)
class DroneConfig:
    """FlyAgent drones (agents.md 1, 3, 4, 14): physics, sensing, start layout and water."""

    num_drones: int = num(4, 1, 64, doc="drones per env")
    max_speed: float = num(10.0, 0.0, lo_open=True, doc="v_max per axis (m/s)")
    view_range: int = num(10, 2, doc="view range (cells)")
    drone_size: float = num(2.0, 0.0, lo_open=True, doc="drone radius used by the collision test (m)")
    use_vel_bins: bool = True  # actions rounded to 41 levels (steps of 0.05)
    use_velocity_change: bool = False  # acceleration mode: v += a * (v_max / 2) * dt
    groundstation_start_percentage: float = num(1.0, 0.0, 1.0, doc="chance a drone starts at the groundstation")
    use_water_limit: bool = False  # finite tank, newest code (agents.md 14); off in the thesis experiments
    water_capacity: float = num(4.0, 0.0, lo_open=True, doc="tank size in drops (one drop puts out one cell)")
    recharge_time: float = num(2.0, 0.0, doc="seconds an empty tank takes to refill at the groundstation")


@dataclass(frozen=True)
class MapConfig:
    """Which land-cover map to simulate."""

    name: str = "35x36_Woods"  # bundled map name, "uniform", or a path to a CLC+ GeoTIFF
    band: int = num(0, 0, doc="raster band (1-based) for multi-band files; 0 = the only band")
    uniform_rows: int = num(50, 1, doc="rows of the uniform map")
    uniform_cols: int = num(50, 1, doc="columns of the uniform map")


@dataclass(frozen=True)
class SimConfig:
    """Batch size, seed and where the kernels run."""

    envs: int = num(1, 1, doc="environments advanced together")
    seed: int = num(0, 0, 2**31 - 1, doc="seed of every random stream")
    arch: str = choice("cpu", ("cpu", "cuda", "vulkan", "auto"))
    threads: int = num(0, 0, doc="CPU threads; 0 = all cores")


@dataclass(frozen=True)
class Config:
    """A whole run: map, fire physics, wind, ignition and the simulator batch."""

    map: MapConfig = field(default_factory=MapConfig)
    fire: FireConfig = field(default_factory=FireConfig)
    wind: WindConfig = field(default_factory=WindConfig)
    ignition: IgnitionConfig = field(default_factory=IgnitionConfig)
    drones: DroneConfig = field(default_factory=DroneConfig)
    sim: SimConfig = field(default_factory=SimConfig)


# ---------------------------------------------------------------------------------------------- loading


def load_config(path: str | Path | None = None, overrides: list[str] | tuple[str, ...] = (), cls: type = Config):
    """Load ``path`` (YAML) into ``cls``, apply ``key.sub=value`` overrides and validate everything.

    Raises:
        ConfigError: naming the file, the key and what was expected.
    """
    data: dict = {}
    where = "--set" if overrides else "defaults"
    if path is not None:
        where = str(path)
        try:
            text = Path(path).read_text()
        except OSError as exc:
            raise ConfigError(f"{path}: cannot read config file ({exc.strerror})") from exc
        try:
            data = yaml.safe_load(text) or {}
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: not valid YAML ({exc})") from exc
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: expected a mapping of sections at the top level, got {type(data).__name__}")
    for item in overrides:
        _apply_override(data, item, cls)
    return from_dict(cls, data, where=where)


def apply_overrides(cfg, overrides: list[str] | tuple[str, ...], where: str = "--set"):
    """A copy of the config ``cfg`` with ``section.key=value`` overrides applied and validated."""
    data = to_dict(cfg)
    for item in overrides:
        _apply_override(data, item, type(cfg))
    return from_dict(type(cfg), data, where=where)


def from_dict(cls: type, data: dict, where: str = "config", prefix: str = ""):
    """Build dataclass ``cls`` from a nested dict; unknown keys, wrong types and out-of-range values raise."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: {prefix or 'top level'} must be a mapping, got {data!r}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    hints = typing.get_type_hints(cls)
    for key in data:
        if key not in fields:
            valid = [prefix + name for name in fields]
            raise ConfigError(f"{where}: unknown key {prefix + str(key)!r}{_suggest(prefix + str(key), valid)}")
    kwargs = {}
    for name, value in data.items():
        hint = hints[name]
        full = f"{prefix}{name}"
        if dataclasses.is_dataclass(hint):
            kwargs[name] = from_dict(hint, value if value is not None else {}, where, full + ".")
        else:
            kwargs[name] = _check_value(_coerce(value, hint, where, full), fields[name], where, full)
    return cls(**kwargs)


def to_dict(cfg) -> dict:
    """A plain nested dict of a config (for YAML/JSON output)."""
    return dataclasses.asdict(cfg)


def dump_config(cfg, path: str | Path) -> None:
    """Write the resolved config as YAML."""
    Path(path).write_text(yaml.safe_dump(to_dict(cfg), sort_keys=False))


def replace(cfg, **changes):
    """``dataclasses.replace`` that re-validates the changed fields."""
    return from_dict(type(cfg), {**to_dict(cfg), **changes}, where="replace")


def all_keys(cls: type = Config, prefix: str = "") -> list[str]:
    """Every dotted key of a config class (for help texts and suggestions)."""
    keys = []
    for f in dataclasses.fields(cls):
        hint = typing.get_type_hints(cls)[f.name]
        if dataclasses.is_dataclass(hint):
            keys += all_keys(hint, f"{prefix}{f.name}.")
        else:
            keys.append(prefix + f.name)
    return keys


def _apply_override(data: dict, item: str, cls: type) -> None:
    if "=" not in item:
        raise ConfigError(f"--set {item!r}: expected section.key=value")
    dotted, raw = item.split("=", 1)
    parts = dotted.strip().split(".")
    if dotted.strip() not in all_keys(cls):
        raise ConfigError(f"--set: unknown key {dotted.strip()!r}{_suggest(dotted.strip(), all_keys(cls))}")
    node = data
    for p in parts[:-1]:
        node = node.setdefault(p, {})
        if not isinstance(node, dict):
            raise ConfigError(f"--set {item!r}: {p!r} is not a section")
    try:
        node[parts[-1]] = yaml.safe_load(raw)
    except yaml.YAMLError as exc:
        raise ConfigError(f"--set {item!r}: cannot parse value ({exc})") from exc


def _suggest(key: str, valid) -> str:
    close = difflib.get_close_matches(key, list(valid), n=1, cutoff=0.5)
    if not close and "." in key:
        close = difflib.get_close_matches(key.split(".")[-1], [v.split(".")[-1] for v in valid], n=1, cutoff=0.5)
    return f"; did you mean {close[0]!r}?" if close else f"; valid keys: {', '.join(sorted(valid))}"


def _as_float(value: Any) -> float | None:
    """A number, or a string like "3e-5" (YAML 1.1 reads an exponent without a dot as a string); else None."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return None
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
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
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
    if not meta or value is None:
        return value
    if meta.get("choices") is not None and value not in meta["choices"]:
        raise ConfigError(f"{where}: {key} = {value!r}; expected one of {', '.join(map(str, meta['choices']))}")
    lo, hi = meta.get("lo"), meta.get("hi")
    if isinstance(value, (int, float)) and value != value:  # NaN compares false with everything
        raise ConfigError(f"{where}: {key} is NaN; expected {_range_text(meta)}")
    too_low = lo is not None and (value <= lo if meta["lo_open"] else value < lo)
    too_high = hi is not None and (value >= hi if meta["hi_open"] else value > hi)
    if too_low or too_high:
        raise ConfigError(f"{where}: {key} = {value!r} is out of range; expected {_range_text(meta)}"
                          + (f" ({meta['doc']})" if meta.get("doc") else ""))
    return value


def _range_text(meta: dict) -> str:
    lo, hi = meta["lo"], meta["hi"]
    left = "(" if meta["lo_open"] else "["
    right = ")" if meta["hi_open"] else "]"
    if hi is None:
        return f"{'>' if meta['lo_open'] else '>='} {lo}"
    if lo is None:
        return f"{'<' if meta['hi_open'] else '<='} {hi}"
    return f"a value in {left}{lo}, {hi}{right}"
