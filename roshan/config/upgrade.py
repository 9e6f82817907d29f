"""Config dicts written by earlier versions, brought to the current tree before validation: the config.yaml of
an old run folder (``--resume``) and the config stored in an old checkpoint (the shipped models/).

- Until PPO became one class for both levels, the planner's PPO had its own section ``planner_ppo`` (the same keys
as ``ppo`` without the FlyAgent-only ones, plus ``network``, other defaults) and ignored ``ppo``.
- Keys added after runs were saved whose default is not what those runs did (a field's ``was=``): a checkpoint's
  config is complete, so one without such a key was saved before the key existed and keeps the behaviour it had.
- Until the config tree became one, training took its batch and seed from ``train.num_envs`` / ``train.seed``
  and silently ignored ``sim.envs`` / ``sim.seed``, which ``roshan simulate`` and the envs read. Now every
  command reads ``sim.envs`` / ``sim.seed``.
"""

from roshan.config.levels import ALGO_LEVELS, PLANNER

# Old dotted key -> its key now (also applied to ``--set`` overrides).
MOVED_KEYS = {"train.num_envs": "sim.envs", "train.seed": "sim.seed"}

# The old PlannerPPOConfig defaults that differ from PPOConfig's (thesis Table 5.8 / P3): a ``planner_ppo``
# section that left them out meant these.
OLD_PLANNER_PPO_DEFAULTS = {"lr": 1e-4, "horizon": 4800, "batch_size": 1200, "gamma": 0.99, "lam": 0.98,
                            "value_loss_coef": 0.001, "entropy_coeff": 0.0005}


def fill_values_of_record(data: dict, record: dict) -> dict:
    """A checkpoint's (complete) config dict with the value of record (``record``: dotted key -> the default it had
    before it changed, :func:`roshan.config.schema.values_of_record`) of each key it lacks: it was saved before the
    key existed, and its run did what that value does. A section it lacks stays absent."""
    for dotted, then in record.items():
        *sections, key = dotted.split(".")
        node = data
        for s in sections:
            node = node.get(s) if isinstance(node, dict) else None
        if isinstance(node, dict) and key not in node:
            data = _with_key(data, sections, key, then)
    return data


def _with_key(data: dict, sections: list[str], key: str, value) -> dict:
    """A copy of ``data`` with ``value`` at ``sections`` / ``key`` (the caller's dict is left as it was)."""
    if not sections:
        return {**data, key: value}
    return {**data, sections[0]: _with_key(data[sections[0]], sections[1:], key, value)}


def upgrade_config_dict(data: dict) -> dict:
    """``data`` in the current layout: moved keys (:data:`MOVED_KEYS`) at their new place (an old training run
    read the old key, so its value wins), then the old planner section (:func:`upgrade_planner_ppo`)."""
    for old, new in MOVED_KEYS.items():
        data = _move_key(data, old, new)
    return upgrade_planner_ppo(data)


def _move_key(data: dict, old: str, new: str) -> dict:
    (old_section, old_key), (new_section, new_key) = old.split("."), new.split(".")
    section = data.get(old_section)
    if not isinstance(section, dict) or old_key not in section:
        return data
    data = dict(data)
    section = dict(section)
    value = section.pop(old_key)
    data[old_section] = section
    data[new_section] = {**(data.get(new_section) or {}), new_key: value}
    return data


def upgrade_planner_ppo(data: dict) -> dict:
    """``data`` with an old ``planner_ppo`` section moved: its ``network`` to ``planner.network``, and, for a
    planner run, the rest (with the old defaults filled in) to ``ppo``, replacing the FlyAgent ``ppo`` section
    that such a run never read. A dict without ``planner_ppo`` comes back unchanged."""
    if "planner_ppo" not in data:
        return data
    data = dict(data)
    old = dict(data.pop("planner_ppo") or {})
    network = old.pop("network", None)
    if network is not None:
        data["planner"] = {**(data.get("planner") or {}), "network": network}
    if _had_planner_ppo((data.get("train") or {}).get("algo")):
        data["ppo"] = {**OLD_PLANNER_PPO_DEFAULTS, **old}
    return data


def upgrade_agent_state(algo: str, agent):
    """An old planner PPO's single ``optimizer`` / ``scheduler`` as the lists of the one PPO class (the network
    weights are untouched); any other agent state comes back as it is."""
    if not (_had_planner_ppo(algo) and isinstance(agent, dict) and "optimizer" in agent):
        return agent
    rest = {k: v for k, v in agent.items() if k not in ("optimizer", "scheduler")}
    return {**rest, "optimizers": [agent["optimizer"]], "schedulers": [agent["scheduler"]]}


def _had_planner_ppo(algo) -> bool:
    """Whether runs of ``algo`` were trained by the old planner PPO (the one place the upgrade asks the level)."""
    return ALGO_LEVELS.get(algo) is PLANNER
