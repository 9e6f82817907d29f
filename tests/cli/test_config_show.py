"""`roshan config show [SECTION]`: every config key with its default, type, allowed values and doc."""

from click.testing import CliRunner

from roshan.cli import main
from roshan.config import all_keys


def show(*args):
    return CliRunner().invoke(main, ["config", "show", *args], catch_exceptions=False)


def row(output: str, key: str) -> list[str]:
    (line,) = [ln for ln in output.splitlines() if ln.split()[:1] == [key]]
    return line.split()


def test_a_section_lists_its_keys_with_default_type_range_and_doc():
    res = show("fire")
    assert res.exit_code == 0, res.output
    assert row(res.output, "fire.dt")[:4] == ["fire.dt", "float", "0.1", "(0.0,"]  # range (0, 10], doc follows
    assert "10.0]" in row(res.output, "fire.dt") and "time step (s)" in res.output
    assert row(res.output, "fire.convection.enabled")[:4] == ["fire.convection.enabled", "bool", "true", "true"]
    assert "wind.speed" not in res.output  # only the section asked for
    planner = show("planner.rewards").output
    assert row(planner, "planner.rewards.preset")[3:6] == ["optuna_best", "|", "optuna_top10"]
    assert all(k.startswith("planner.rewards.") for k in all_keys() if f"\n{k} " in planner)


def test_everything_is_listed_and_documented_from_the_source_comments():
    res = show()
    listing, profiles = res.output.split("\nprofile: a base layer")  # the keys, then the profiles and their values
    headings = ("top level:",)  # a section heading is "name: its doc"; the root's is "top level: ..."
    rows = [ln.split()[0] for ln in listing.splitlines()[1:]
            if ln and not ln.split()[0].endswith(":") and not ln.startswith(headings)]
    assert sorted(rows) == sorted(all_keys())
    assert "thesis: " in profiles and "fly.sticky_extinguish" in profiles
    assert "emit_convective" in " ".join(row(res.output, "fire.convection.enabled"))  # a `# comment` is the doc
    assert show("fire.dt").output.count("fire.dt") == 1  # one key


def test_an_unknown_section_is_one_error_with_a_suggestion():
    res = show("fir")
    assert res.exit_code != 0 and "unknown config section 'fir'" in res.output and "did you mean 'fire'" in res.output
    res = show("zzz")
    assert res.exit_code != 0 and "sections: map, fire," in res.output


def test_every_key_has_a_doc():
    """`config show` documents every key (issue 32, item 17): a new key needs a `doc=` or a `# comment`."""
    from roshan.config import Config
    from roshan.config.describe import describe_keys

    undocumented = [r["key"] for r in describe_keys(Config) if not r["doc"].strip()]
    assert undocumented == [], f"config keys without a doc: {undocumented}"
    assert "evaluation" in " ".join(row(show("train.eval_episodes").output, "train.eval_episodes"))
