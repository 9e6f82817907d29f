"""The training progress bar ends where training ends: at the budget that runs out first. With
train.max_minutes = 1.5 it read "38912/600000 [00:57<19:02" (the bar of train.total_steps) and stopped at 1.5 min."""

from roshan.config.learning import TrainConfig
from roshan.runs.budget import budget_total
from roshan.runs.train import Progress


def progress(updates: int, env_steps: int, seconds: float) -> Progress:
    p = Progress()
    p.updates, p.env_steps, p.seconds = updates, env_steps, seconds
    return p


def test_the_bar_ends_at_the_budget_that_binds():
    minutes = TrainConfig(total_steps=600_000, max_minutes=1.5, max_updates=0)
    # 38,912 env steps in 57 s: 1.5 min ends near 61,440, long before 600,000
    assert budget_total(minutes, progress(19, 38_912, 57.0), 2_048, True) == round(38_912 * 90 / 57)
    steps = TrainConfig(total_steps=600_000, max_minutes=0, max_updates=0)
    assert budget_total(steps, progress(19, 38_912, 57.0), 2_048, True) == 600_000
    updates = TrainConfig(total_steps=600_000, max_minutes=0, max_updates=30)
    assert budget_total(updates, progress(10, 20_480, 30.0), 2_048, True) == 20_480 + 20 * 2_048
    # a learner that takes no env step (offline IQL) counts updates
    assert budget_total(TrainConfig(total_steps=0, max_minutes=0, max_updates=30), progress(10, 0, 5.0), 0, False) == 30
    unbounded = TrainConfig(total_steps=0, max_minutes=0, max_updates=0)
    assert budget_total(unbounded, progress(1, 10, 1.0), 10, True) is None
    # before the first update nothing projects the time budget; the bar then has no end yet
    timed = TrainConfig(total_steps=0, max_minutes=1.5, max_updates=0)
    assert budget_total(timed, progress(0, 0, 0.0), 0, True) is None
