"""`roshan simulate`'s summary gives its rate over the run's wall time (it printed "in 0.05 s: 65,270 env-steps/s"
for an 18 s run: the time of the updates alone), and the updates' own rate beside it."""

import time

from roshan.tools.simulate import SimulationResult, summary_lines, timing


def test_the_rate_is_over_the_wall_time_with_the_updates_alone_beside_it():
    t0 = time.perf_counter() - 18.0  # a run that started 18 s ago, of which 0.05 s were updates
    t = timing(steps=3264, envs=1, t_reset=17.0, step_seconds=0.05, memory=196_608, t0=t0)
    assert 18.0 <= t["wall_s"] < 19.0 and t["wall_env_steps_per_s"] == 3264 / t["wall_s"]
    record = {"time_s": 326.4, "burning": [3], "burned": [5], "convection": [1], "radiation": [2],
              "dropped_convection": [0], "dropped_radiation": [0]}
    line = summary_lines(SimulationResult(series=[record], timing=t))[0]
    assert f"in {t['wall_s']:.2f} s: {t['wall_env_steps_per_s']:,.0f} env-steps/s" in line
    assert "the updates alone: 0.05 s, 65,280 env-steps/s" in line
