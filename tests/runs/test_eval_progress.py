"""The evaluation progress bar moves with the steps of running episodes, not only when one finishes."""

import io

import pytest
import torch
from tqdm import tqdm

from roshan.runs.evaluate import _advance_bar


def test_the_eval_bar_counts_finished_episodes_plus_the_share_of_running_ones():
    bar = tqdm(total=4, file=io.StringIO())  # quota 2 episodes x 2 envs
    done = torch.tensor([0, 0])
    _advance_bar(bar, done, torch.tensor([25, 50]), quota=2, t_max=100)
    assert bar.n == pytest.approx(0.75)  # no episode has ended, and the bar has moved
    _advance_bar(bar, done, torch.tensor([100, 200]), quota=2, t_max=100)
    assert bar.n == pytest.approx(2 * 0.99)  # a running episode never counts as a whole one
    _advance_bar(bar, torch.tensor([2, 1]), torch.tensor([7, 10]), quota=2, t_max=100)
    assert bar.n == pytest.approx(3.1)  # env 0 done (its steps no longer count), env 1 10 % into its 2nd
