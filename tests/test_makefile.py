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
    # 8 episodes are often a tie: the demo points to the figures to quote, where the planner wins
    assert "figures to quote" in command and "planner_endurance 78 %" in command and "greedy's 71 %" in command
    readme = (ROOT / "README.md").read_text()
    (line,) = [ln for ln in readme.splitlines() if ln.startswith("make demo")]
    assert "8 fires" not in readme and "8 episodes" in line
    assert "thesis setting" in readme and "planner.greedy_home: fixed" in readme


def test_print_torch_names_the_build_from_the_machine(venv):
    """No NVIDIA GPU: the CPU build; nvidia-smi found: the CUDA build; TORCH_INDEX: that index. `make install` hands
    the same choice to scripts/install_torch.sh (make -n: nothing runs), and the choice is part of the stamp."""
    env = base_env(venv / "bin")
    assert make("print-torch", "NVIDIA_SMI=/nonexistent", env=env).stdout.strip() == "torch: cpu build of torch==2.13.0"
    assert make("print-torch", "NVIDIA_SMI=true", env=env).stdout.strip() == "torch: cuda build of torch==2.13.0"
    line = make("print-torch", "TORCH_INDEX=https://example.invalid/cpu", env=env).stdout.strip()
    assert line == "torch: index build of torch==2.13.0 from https://example.invalid/cpu"
    dry = make("-n", "install", "NVIDIA_SMI=/nonexistent", env=env).stdout
    assert 'NVIDIA_SMI="/nonexistent" sh scripts/install_torch.sh' in dry
    stamps = {make("print-python", f"NVIDIA_SMI={probe}", env=env).stdout.split()[1]
              for probe in ("/nonexistent", "true")}
    assert len(stamps) == 2  # a machine that gains a GPU installs again


FAKE_PYTHON = """#!/bin/sh
# python stand-in: records every pip call; a dry run reports $OFFERED; an install from --index-url fails if $DOWN.
if [ "$1" = "-m" ] && [ "$2" = "pip" ]; then
    shift 2
    echo "pip $*" >> "$LOG"
    case "$*" in
        *--dry-run*) printf '{"install": [{"metadata": {"version": "%s"}}]}' "$OFFERED"; exit 0;;
        *--index-url*) [ -z "$DOWN" ] || exit 1;;
    esac
    exit 0
fi
exec "$REAL" "$@"
"""


@pytest.mark.parametrize("gpu, offered, down, expected, installs", [
    (True, "2.13.0", "", "the CUDA build", ["pip install -q torch==2.13.0"]),
    (False, "2.13.0+cpu", "", "the configured index serves 2.13.0+cpu", ["pip install -q torch==2.13.0"]),
    (False, "2.13.0", "", "from https://download.pytorch.org/whl/cpu",
     ["pip install -q torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu"]),
    (False, "2.13.0", "1", "cannot be reached; torch==2.13.0 from the configured index instead",
     ["pip install -q torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu", "pip install -q torch==2.13.0"]),
])
def test_the_torch_install_takes_the_cpu_build_without_a_gpu(tmp_path, gpu, offered, down, expected, installs):
    """scripts/install_torch.sh with a stand-in pip (nothing is downloaded): without an NVIDIA GPU the CPU build,
    from the configured index when it serves one (this project's CI: a +cpu wheel in its local store), else from
    PyTorch's CPU index, else, that index unreachable, the configured one; one line says which."""
    fake = tmp_path / "python"
    fake.write_text(FAKE_PYTHON)
    fake.chmod(0o755)
    log = tmp_path / "pip.log"
    env = {"PATH": os.environ["PATH"], "PYTHON": str(fake), "REAL": sys.executable, "LOG": str(log),
           "OFFERED": offered, "DOWN": down, "NVIDIA_SMI": "true" if gpu else str(tmp_path / "no-nvidia-smi")}
    out = subprocess.run(["sh", str(ROOT / "scripts" / "install_torch.sh")], env=env, capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    assert expected in out.stdout and out.stdout.startswith("torch: ")
    calls = [c for c in log.read_text().splitlines() if "--dry-run" not in c]
    assert calls == installs
