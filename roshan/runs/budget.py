"""Where a training run's progress bar ends: the budget (train.total_steps, train.max_updates, train.max_minutes)
that runs out first, projected from the run's progress so far."""

from roshan.config.learning import TrainConfig


def budget_total(tc: TrainConfig, progress, steps_per_update: int, counts_env_steps: bool) -> int | None:
    """Where the progress bar ends: the env steps (or, for a learner that takes none, the updates) at which the
    first budget to run out stops training, as far as it can be told now: ``train.total_steps``,
    ``train.max_updates`` times the steps of the last update, or ``train.max_minutes`` at the rate so far. None
    when no budget is set (or none can be projected yet)."""
    done = progress.env_steps if counts_env_steps else progress.updates
    per_update = steps_per_update if counts_env_steps else 1
    ends = []
    if tc.total_steps > 0 and counts_env_steps:
        ends.append(tc.total_steps)
    if tc.max_updates > 0 and per_update > 0:
        ends.append(done + (tc.max_updates - progress.updates) * per_update)
    if tc.max_minutes > 0 and progress.seconds > 0 and done > 0:
        ends.append(round(done * 60.0 * tc.max_minutes / progress.seconds))
    return max(done, min(ends)) if ends else None
