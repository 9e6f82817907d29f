"""The Makefile's choice of Python and its install stamp, read with `make print-python` and `make -q` (nothing is
installed): an active virtualenv is used, else the checkout's own .venv; a second install is a no-op."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="no make")


def make(*args, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(["make", "-s", "--no-print-directory", "-C", str(ROOT), *args], env=env,
                          capture_output=True, text=True, timeout=60)


def base_env(path_first: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV", "PYTHON", "TORCH_INDEX", "MAKEFLAGS")}
    env["PATH"] = f"{path_first}{os.pathsep}{env.get('PATH', '')}"
    return env


@pytest.fixture
def system_python(tmp_path) -> Path:
    """A folder whose python3 is the interpreter under every virtualenv (Debian's /usr/bin/python3 or the like)."""
    folder = tmp_path / "system"
    folder.mkdir()
    base = Path(sys.base_prefix) / "bin" / "python3"
    if not base.exists():
        pytest.skip(f"no {base}")
    (folder / "python3").symlink_to(base)
    return folder


@pytest.fixture
def venv(tmp_path) -> Path:
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(tmp_path / "venv")], check=True)
    return tmp_path / "venv"


def test_without_a_virtualenv_the_checkout_gets_its_own(system_python):
    python, stamp = make("print-python", env=base_env(system_python)).stdout.split()
    assert python == str(ROOT / ".venv/bin/python") and stamp.startswith(str(ROOT / ".venv/.roshan-installed-"))


def test_an_active_virtualenv_is_used(system_python, venv):
    env = base_env(system_python)
    python, _ = make("print-python", env={**env, "VIRTUAL_ENV": str(venv)}).stdout.split()
    assert python == f"{venv}/bin/python"
    # fresh-check and CI: VIRTUAL_ENV unset, the venv's python3 first on PATH
    python, stamp = make("print-python", env=base_env(venv / "bin")).stdout.split()
    assert python == "python3" and Path(stamp).parent == venv
    python, _ = make("print-python", "PYTHON=/opt/py/bin/python3", env=env).stdout.split()
    assert python == "/opt/py/bin/python3"


def test_the_stamp_makes_a_second_install_a_no_op_until_something_changes(venv):
    env = base_env(venv / "bin")
    _, stamp = make("print-python", env=env).stdout.split()
    assert make("-q", "install", env=env).returncode == 1  # nothing installed yet
    Path(stamp).touch()  # what a finished install leaves
    assert make("-q", "install", env=env).returncode == 0
    assert make("-q", "install", "TORCH_INDEX=https://example.invalid/cpu", env=env).returncode == 1


def test_the_demo_says_what_it_runs(venv):
    """`make demo` is 8 episodes of the thesis setting against the fixed greedy heuristic, and the README's line
    about it says so (issue 32, items 10 and 12; the shipped planner is the thesis setting's since issue 30, whose
    config keeps the original heuristic, so the demo names the fixed one)."""
    env = base_env(venv / "bin")
    _, stamp = make("print-python", env=env).stdout.split()
    Path(stamp).touch()  # installed: -n then prints the demo's own command alone
    command = " ".join(make("-n", "demo", env=env).stdout.replace("\\\n", " ").split())
    assert "--episodes 8 --envs 8" in command and "--baseline greedy" in command
    assert "planner.greedy_home=fixed" in command
    readme = (ROOT / "README.md").read_text()
    (line,) = [ln for ln in readme.splitlines() if ln.startswith("make demo")]
    assert "8 fires" not in readme and "8 episodes" in line
    assert "thesis setting" in readme and "planner.greedy_home: fixed" in readme
