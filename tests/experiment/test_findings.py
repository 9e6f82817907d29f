"""The findings' statistics: the intervals against worked examples, and the verdicts they give: a clear difference
holds (or fails), a tie within noise and two rates pinned at 100 % are not resolved, and every verdict line carries
the statistic that decides it."""

import math

import numpy as np
import pytest

from roshan.experiment.findings import (
    Finding,
    difference,
    estimate,
    findings_markdown,
    judge,
    parse_findings,
    sample,
    setting_line,
    verdict,
)
from roshan.experiment.intervals import (
    bootstrap_medians,
    newcombe_interval,
    over_episodes,
    over_seeds,
    t_interval,
    welch_interval,
)
from roshan.experiment.spec import Reference
from roshan.runs.report.stats import t_quantile


def result(success: float, episodes: int = 100, tte=None, controller: str = "policy") -> dict:
    """A run's result as the runner stores it: ``success`` of ``episodes``, the rest timeouts."""
    tte = [1000] * episodes if tte is None else [int(t) for t in tte]
    return {"controller": controller, "episodes": episodes, "success_rate": success,
            "failure_rates": {"timeout": 1.0 - success}, "tte_episodes": tte}


def finding(*checks: str, conditions=("A", "B", "greedy")) -> Finding:
    (f,) = parse_findings([{"claim": "c", "source": "s", "holds": list(checks)}], set(conditions), "spec")
    return f


# ------------------------------------------------------------------------------------------ the intervals


def test_newcombe_interval_matches_newcombes_worked_examples():
    # Newcombe (1998), Statistics in Medicine 17, Table II, method 10: 56/70 - 48/80 and 9/10 - 3/10
    assert newcombe_interval(56, 70, 48, 80) == pytest.approx((0.0524, 0.3339), abs=5e-5)
    assert newcombe_interval(9, 10, 3, 10) == pytest.approx((0.1705, 0.8090), abs=5e-5)


def test_welch_interval_by_hand():
    a, b = np.array([1.0, 2, 3, 4]), np.array([2.0, 4, 6])
    # variances of the means 5/12 and 4/3; Welch-Satterthwaite df = 1.75^2 / ((5/12)^2 / 3 + (4/3)^2 / 2)
    df = 1.75 ** 2 / ((5 / 12) ** 2 / 3 + (4 / 3) ** 2 / 2)
    half = t_quantile(0.975, df) * math.sqrt(1.75)
    lo, hi = welch_interval(over_episodes([a]), over_episodes([b]))
    assert (lo, hi) == pytest.approx((-1.5 - half, -1.5 + half))
    assert (lo, hi) == pytest.approx((-5.5423, 2.5423), abs=5e-5)  # scipy's ttest_ind(equal_var=False) says so
    # three seeds of a mean: the t interval over the seeds' means, df 2
    part = over_seeds([np.array([1.0, 3]), np.array([4.0, 6]), np.array([7.0, 9])])
    assert (part.mean, part.var, part.df) == (5.0, 3.0, 2)
    assert t_interval(part) == pytest.approx((5 - 4.302653 * math.sqrt(3), 5 + 4.302653 * math.sqrt(3)))


def test_a_rate_is_wilson_over_pooled_episodes_widened_by_the_seed_spread():
    one = sample([result(0.92)], "success", "best")
    s = estimate(one, "success")  # one seed: its episodes' Wilson interval only, 92/100 -> [85.0, 95.9]
    assert (s.value, round(s.lo, 1), round(s.hi, 1)) == (92.0, 85.0, 95.9)
    two = sample([result(0.8), result(1.0)], "success", "best")
    s = estimate(two, "success")  # seeds 80 and 100: mean 90 ± 12.706 x 10 (t, df 1), kept within [0, 100]
    assert (s.value, s.lo, s.hi) == (90.0, 0.0, 100.0)


def test_the_median_bootstrap_is_seeded_and_exact_on_constant_episodes():
    seeds = [np.arange(100.0), np.arange(50.0, 150.0)]
    assert np.array_equal(bootstrap_medians(seeds), bootstrap_medians(seeds))
    assert np.all(bootstrap_medians([np.full(10, 7.0)]) == 7.0)
    ragged = bootstrap_medians([np.arange(10.0), np.arange(100.0, 130.0)], reps=500)  # unequal episode counts
    assert ragged.shape == (500,) and np.isfinite(ragged).all()


# ------------------------------------------------------------------------------------------ the verdicts


def test_a_clear_difference_holds_and_its_reverse_fails():
    by = {"A": [result(0.95)], "B": [result(0.5)]}
    lo, hi = newcombe_interval(95, 100, 50, 100)
    assert verdict(finding("A.success > B.success"), by, "best").label == "confirmed"
    v = verdict(finding("A.success < B.success"), by, "best")
    assert v.label == "contradicted"
    assert v.why == (f"A.success < B.success, difference +45.0 points, 95 % CI [{100 * lo:+.1f}, {100 * hi:+.1f}] "
                     "(1 check: fails)")
    a, b = sample(by["A"], "success", "best"), sample(by["B"], "success", "best")
    assert judge(finding("A.success > B.success").checks[0], a, b).outcome == "holds"


def test_a_tie_within_noise_is_not_resolved():
    by = {"A": [result(0.90), result(0.92), result(0.94)], "B": [result(0.91)]}
    v = verdict(finding("A.success > B.success"), by, "best")
    assert (v.label, v.reasons) == ("not resolved", "a tie within noise")
    assert v.checks[0].endswith(": not resolved, a tie within noise")
    d = difference(sample(by["A"], "success", "best"), sample(by["B"], "success", "best"), "success")
    assert d.lo < 0 < d.hi and d.value == pytest.approx(1.0)


def test_rates_both_at_100_or_0_are_saturated_not_confirmed():
    by = {"A": [result(1.0)] * 3, "B": [result(1.0)]}
    for op in (">", ">="):  # a tie confirms neither
        v = verdict(finding(f"A.success {op} B.success"), by, "best")
        assert (v.label, v.reasons) == ("not resolved", "saturated, both at 100 %")
    v = verdict(finding("A.timeout < B.timeout", "A.timeout >= 0"), by, "best")
    assert v.reasons == "saturated, both at 0 %" and v.checks[1].startswith("A.timeout 0.0 [0.0, 1.3] >= 0: ")
    v = verdict(finding("A.timeout < B.timeout", "A.success > 99"), by, "best")  # 99 is inside A's interval
    assert v.reasons == "a tie within noise; saturated, both at 0 %"
    v = verdict(finding("A.success > B.success", "A.timeout < B.timeout"), by, "best")
    assert v.reasons == "saturated, both at 100 % or 0 %"
    v = verdict(finding("A.timeout < B.timeout", "A.success < 90"), by, "best")  # one check fails outright
    assert v.label == "contradicted" and v.why.startswith("A.success < 90, difference +10.0 points")


def test_median_tte_differences_are_judged_by_the_bootstrap():
    rng = np.random.default_rng(1)
    fast = [result(1.0, tte=rng.normal(900, 100, 100)) for _ in range(3)]
    slow = [result(1.0, tte=rng.normal(1200, 100, 100))]
    same = [result(1.0, 300, tte=np.concatenate([r["tte_episodes"] for r in fast]))]  # A's episodes, pooled
    assert verdict(finding("A.tte_median < B.tte_median"), {"A": fast, "B": slow}, "best").label == "confirmed"
    v = verdict(finding("A.tte_median < B.tte_median"), {"A": fast, "B": same}, "best")
    assert v.label == "not resolved" and "steps, 95 % CI [" in v.why


def test_a_scripted_controller_serves_every_set_of_weights_and_missing_weights_are_untested():
    by = {"A": [result(0.95)], "B": [result(0.5, controller="greedy")]}
    assert verdict(finding("A.success > B.success"), by, "last").label == "untested"  # A has no last weights
    by["A"][0]["last"] = {"success_rate": 0.95, "failure_rates": {"timeout": 0.05}, "tte_episodes": [1000] * 100}
    assert verdict(finding("A.success > B.success"), by, "last").label == "confirmed"


def test_a_verdict_line_carries_its_statistic_and_the_setting_is_set_against_the_thesis():
    by = {"A": [result(0.95, controller="nearest")], "B": [result(0.5, controller="nearest")],
          "greedy": [result(0.92, controller="greedy")]}
    f = finding("A.success > B.success", "A.success > greedy.success")
    text = findings_markdown((f,), by, {"A": (1, 1), "B": (1, 1), "greedy": (1, 1)},
                             {"greedy": {"success": Reference(73.0), "tte": Reference(1860, 1104, 1381)}})
    lo, hi = newcombe_interval(95, 100, 92, 100)
    assert (f"  - best, last, objective: **not resolved** (a tie within noise): A.success > greedy.success, "
            f"difference +3.0 points, 95 % CI [{100 * lo:+.1f}, {100 * hi:+.1f}] (2 checks: 1 holds, 1 not resolved)"
            ) in text
    assert "    - A.success 95.0 [88.8, 97.8] > B.success 50.0 [40.4, 59.6]: difference +45.0 points" in text
    line = setting_line("greedy", by["greedy"], {"success": Reference(73.0), "tte": Reference(1860, 1104, 1381)})
    assert line.startswith("Our setting against the thesis's: greedy succeeds in 92.0 % of 100 episodes (95 % CI "
                           "[85.0, 95.9]) against the thesis's 73 %: +19.0 points, 95 % CI [")
    assert "its TTE is 1000 ± 0 (1000) steps against the thesis's 1860 ± 1104 (1381): mean -860 steps" in line
    assert line.endswith("; our episodes are easier for greedy than the thesis's.")
    assert line in text
