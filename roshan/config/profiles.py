"""Named profiles: the settings that reproduce a version of the original, chosen in one place.

The defaults are this project's: every rule that fixes a defect of the original is on. A profile is a base layer
between the defaults and a config file: ``profile: thesis`` in a file (or ``--set profile=thesis``) takes the
profile's values for every key the file and the overrides leave alone, so a file states only where it departs.
Several profiles apply in the order named (``profile: thesis,original``: the thesis-era code with the defects it
shared with the newest code). The run's config.yaml records the profile's name beside the values it resolved to, so
a run folder reloads the same without the profile table; an experiment's fingerprint reads those values, not the
name, so a condition that names a profile instead of listing its keys is the same run. Loading applies a profile
(:func:`roshan.config.load_config`, from a file or ``--set``); a ``Config(profile=...)`` built in Python only records
the name.

``roshan config show profile`` lists them with their values.
"""

from dataclasses import dataclass
from typing import Any

from roshan.config.schema import ConfigError, suggest


@dataclass(frozen=True)
class Profile:
    name: str
    summary: str
    values: dict[str, Any]  # dotted key -> value


THESIS = Profile("thesis", "the thesis-era code that ran the thesis's experiments (docs/model/thesis.md §1)", {
    "ignition.reseed": False,  # a stalled cluster is not re-seeded: the fire percentage is a maximum
    "fly.time_limit": "thesis",  # slack 2.0 and the complex FlyAgent's extra factor
    "planner.time_limit": "thesis",  # beta 0.3, no extra step per fire
    "planner.meander": "thesis",  # cyclic waypoint index, capped last stripe
    "planner.network": "thesis",  # one cross-attention layer
    "planner.rewards.version": "thesis",
    "drones.use_water_limit": False,  # water was future work
    "ppo.max_grad_norm": 0.0,  # its clipping call saw no parameters
    "ppo.reward_eps": 1e-8,
})

NEWEST = Profile("newest", "the newest original code (dec467a)", {
    "ignition.reseed": True,
    "fly.time_limit": "newest",
    "planner.time_limit": "newest",
    "planner.meander": "newest",
    "planner.network": "pointer",
    "planner.rewards.version": "newest",
    "drones.use_water_limit": True,
    "ppo.max_grad_norm": 0.5,
    "ppo.reward_eps": 1e-4,
})

ORIGINAL = Profile("original", "the defects both versions of the original share, which the defaults fix", {
    "fly.sticky_extinguish": True,  # the Extinguish flag stays set after its step
    "planner.greedy_home": "original",  # a fire on the groundstation cell is never put out by the heuristic
    "planner.explorer_index_bound": "first",  # explorer 0's path bounds the shared waypoint index
    "td3.broadcast_defect": True,  # the (B, 1)-vs-(B,) critic target
    "iql.broadcast_defect": True,  # the (B, B) Q target
    "ppo.bootstrap_truncated": False,  # a time-out ends the trace like a terminal
})

PROFILES = {p.name: p for p in (THESIS, NEWEST, ORIGINAL)}


def profile_names(text: str) -> list[str]:
    """The profiles ``text`` names, comma-separated, in order ("" names none).

    Raises:
        ConfigError: for a name that is not a profile, with the closest one.
    """
    names = [n.strip() for n in str(text).split(",") if n.strip()]
    for n in names:
        if n not in PROFILES:
            raise ConfigError(f"profile: unknown profile {n!r}{suggest(n, list(PROFILES))} (the profiles: "
                              f"{', '.join(PROFILES)}; several apply in order, comma-separated)")
    return names


def profile_values(text: str) -> dict[str, Any]:
    """Dotted key -> value of the profiles ``text`` names, a later profile's value over an earlier one's."""
    out: dict[str, Any] = {}
    for n in profile_names(text):
        out.update(PROFILES[n].values)
    return out


def under_profile(data: dict) -> dict:
    """``data`` (a config file's dict with its overrides applied) over the values of the profiles its ``profile``
    key names: a key ``data`` gives keeps its value, any other takes the profile's."""
    values = profile_values(data.get("profile") or "")
    if not values:
        return data
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in data.items()}
    for dotted, value in values.items():
        node = out
        *sections, key = dotted.split(".")
        for s in sections:
            child = node.get(s)
            node[s] = child = dict(child) if isinstance(child, dict) else {}
            node = child
        node.setdefault(key, value)
    return out


def describe_profiles() -> str:
    """``roshan config show profile``: each profile's name, what it reproduces and its values."""
    lines = ["profile: a base layer of settings under a config file (profile: NAME, or several: A,B)"]
    for p in PROFILES.values():
        lines += ["", f"{p.name}: {p.summary}"]
        width = max(len(k) for k in p.values)
        lines += [f"  {k:<{width}}  {_yaml_text(v)}" for k, v in p.values.items()]
    return "\n".join(lines)


def _yaml_text(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)
