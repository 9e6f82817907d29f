"""Commands import what they use and no more (issue 34): the light commands never load torch or gymnasium, and
the Gymnasium id is registered whichever of ``roshan.env`` and ``gymnasium`` is imported first, and ``import roshan``
changes nothing in the process."""

import json
import subprocess
import sys

import pytest

HEAVY = ("torch", "gymnasium")

RUN_AND_LIST = """
import json, sys
from roshan.cli import main
try:
    main({args!r}, standalone_mode=False)
except SystemExit:
    pass
print(json.dumps(sorted(m for m in {heavy!r} if m in sys.modules)))
"""


def loaded_by(args: list[str]) -> list[str]:
    """The heavy modules a fresh interpreter holds after running ``roshan ARGS`` in-process."""
    code = RUN_AND_LIST.format(args=args, heavy=HEAVY)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("args", [
    ["--help"],
    ["maps", "list"],
    ["maps", "show", "35x36_Woods"],
    ["config", "show", "fire"],
    ["simulate", "--map", "35x36_Woods", "--envs", "1", "--steps", "1", "--quiet"],
], ids=lambda a: " ".join(a[:2]))
@pytest.mark.slow
def test_light_commands_import_neither_torch_nor_gymnasium(args):
    assert loaded_by(args) == []


@pytest.mark.slow
def test_drone_simulation_does_load_the_envs():
    """The check above can fail: a command that flies drones needs the env, and so torch and gymnasium."""
    assert loaded_by(["simulate", "--map", "35x36_Woods", "--envs", "1", "--steps", "1", "--drones", "1",
                      "--quiet"]) == ["gymnasium", "torch"]


@pytest.mark.parametrize("first", ["roshan.env", "gymnasium"])
def test_the_gymnasium_id_is_registered_in_either_import_order(first):
    second = "gymnasium" if first == "roshan.env" else "roshan.env"
    code = (f"import {first}, {second}, gymnasium\n"
            "print('roshan/FlyAgent-v0' in gymnasium.registry, gymnasium.__spec__.loader.__class__.__name__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert out.stdout.split() == ["True", "SourceFileLoader"]


def test_importing_roshan_changes_nothing_in_the_process():
    """No import hook, no registration, nothing loaded beyond the package itself; gymnasium.make's ``module:``
    prefix then finds the id (make resolves it through _find_spec, which spec() does not use)."""
    code = ("import sys\nhooks = list(sys.meta_path)\nimport roshan\n"
            "print(sys.meta_path == hooks, sorted(m for m in sys.modules if m.startswith(('roshan', 'gymnasium',"
            " 'taichi', 'torch'))))\n"
            "from gymnasium.envs.registration import _find_spec\n"
            "print(_find_spec('roshan.env:roshan/FlyAgent-v0').entry_point, 'taichi' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    assert out.stdout.splitlines() == ["True ['roshan']", "roshan.env.single:FlyEnv False"], out.stdout
