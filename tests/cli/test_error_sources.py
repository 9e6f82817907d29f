"""Errors name where the bad value came from (issue 32, item 8): a command's own option, --set, or the config
file; `config show` suggests only names close to what was typed; --threads above the machine's cores is said."""

import pytest
from click.testing import CliRunner

from roshan.cli import main
from roshan.config import ConfigError, load_config
from roshan.runtime import cpu_cores


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_a_bad_option_value_names_the_option_not_set():
    r = run("simulate", "--wind-speed", "-3", "--steps", "1", "--quiet")
    assert r.exit_code == 1
    assert "--wind-speed: wind.speed = -3.0 is out of range" in r.output and "--set" not in r.output
    r = run("simulate", "--wind-speed", "3", "--set", "wind.speed=-2", "--steps", "1", "--quiet")
    assert "--set: wind.speed = -2.0" in r.output  # the --set came last and is the bad one


def test_a_bad_set_on_top_of_a_config_file_names_set_not_the_file(tmp_path):
    r = run("train", "configs/fly_simple.yaml", "--set", "ppo.lr=-1", "--root", tmp_path)
    assert r.exit_code == 1
    assert "--set: ppo.lr = -1.0 is out of range" in r.output and "fly_simple.yaml" not in r.output
    bad = tmp_path / "bad.yaml"
    bad.write_text("ppo:\n  lr: -1\n")
    r = run("train", bad, "--set", "ppo.gamma=0.9", "--root", tmp_path)
    assert f"{bad}: ppo.lr = -1.0 is out of range" in r.output  # the file's own bad value still names the file


def test_load_config_flags_name_their_option():
    with pytest.raises(ConfigError, match=r"^--envs: sim\.envs = 0 is out of range"):
        load_config(None, flags={"sim.envs": ("--envs", 0)})
    assert load_config(None, ["sim.envs=3"], flags={"sim.envs": ("--envs", 2)}).sim.envs == 3  # --set wins


@pytest.mark.parametrize("asked, answer", [
    ("nosuchsection", "sections: map, fire,"),
    ("fir", "did you mean 'fire'?"),
    ("fire.dtt", "did you mean 'fire.dt'?"),
    ("ppo.learning_rate", "did you mean 'ppo.lr'?"),
    ("planner.reward", "did you mean 'planner.rewards'?"),
    ("fire.zzzzz", "fire has: convection, radiation, dt,"),
])
def test_config_show_suggests_only_close_names(asked, answer):
    r = run("config", "show", asked)
    assert r.exit_code == 1 and answer in r.output, r.output
    assert "wind.direction" not in r.output


@pytest.mark.slow
def test_threads_beyond_the_cores_are_said():
    r = run("simulate", "--steps", "1", "--quiet", "--threads", cpu_cores() + 997)
    assert r.exit_code == 0, r.output
    assert f"more than the {cpu_cores()} CPU core" in r.output and "slower" in r.output
    r = run("simulate", "--steps", "1", "--quiet", "--threads", 1)
    assert "warning" not in r.output
