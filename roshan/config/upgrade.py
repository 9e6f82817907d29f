"""Config dicts written by earlier versions, brought to the current tree before validation: the config.yaml of
an old run folder (``--resume``) and the config stored in an old checkpoint (the shipped models/).

Until PPO became one class for both levels, the planner's PPO had its own section ``planner_ppo`` (the same keys
as ``ppo`` without the FlyAgent-only ones, plus ``network``, other defaults) and ignored ``ppo``.
"""

# The old PlannerPPOConfig defaults that differ from PPOConfig's (thesis Table 5.8 / P3): a ``planner_ppo``
# section that left them out meant these.
OLD_PLANNER_PPO_DEFAULTS = {"lr": 1e-4, "horizon": 4800, "batch_size": 1200, "gamma": 0.99, "lam": 0.98,
                            "value_loss_coef": 0.001, "entropy_coeff": 0.0005}


def upgrade_config_dict(data: dict) -> dict:
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
    if (data.get("train") or {}).get("algo") == "planner":
        data["ppo"] = {**OLD_PLANNER_PPO_DEFAULTS, **old}
    return data
