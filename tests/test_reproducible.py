"""The reproducible mode (roshan/reproducible.py): torch's CPU kernels pinned so that one config and seed give the
same weights and the same evaluation on every x86-64 CPU. The pins here were recorded on an AMD EPYC and hold,
unchanged, on an Intel Xeon of the same machine kind: there is no table per vendor."""

import csv
import hashlib
import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from roshan import reproducible

ROOT = Path(__file__).resolve().parents[1]
TESTS = Path(__file__).resolve().parent


def fresh_env(mode: bool, **extra: str) -> dict:
    """The environment of a new process in the mode or out of it, plus ``extra``."""
    return {**reproducible.environ(mode), **extra}


def python(code: str, env: dict) -> str:
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout.strip().splitlines()[-1]


def test_the_suite_runs_in_the_mode_and_says_so():
    assert reproducible.check() is None
    m = reproducible.machine()
    assert (m["mode"], m["isa"]) == ("reproducible", "AVX2")
    assert m["cpu"] and m["torch"] == torch.__version__
    assert reproducible.label(m) == m["cpu"]
    assert reproducible.label({**m, "mode": "vendor", "isa": "AVX512"}) == f"{m['cpu']} (AVX512, vendor kernels)"


def test_the_mode_is_refused_once_torch_has_chosen_other_kernels():
    out = python("import torch; torch.ones(4, 4) @ torch.ones(4, 4)\n"
                 "from roshan import reproducible\n"
                 "try:\n    reproducible.enable()\nexcept reproducible.ReproducibleModeError as e:\n    print(e)",
                 fresh_env(False))
    assert "could not be set" in out and "ATEN_CPU_CAPABILITY" in out


UPDATE = ("import sys; sys.path.insert(0, 'tests/algos'); import torch; torch.set_num_threads(1)\n"
          "from test_ppo import update_fingerprint\n"
          "from roshan import reproducible\n"
          "print(reproducible.mode(), update_fingerprint('samples'), update_fingerprint('sequences'))")


@pytest.mark.slow
@pytest.mark.parametrize("offer", [{"MKL_ENABLE_INSTRUCTIONS": "AVX2"}, {"MKL_ENABLE_INSTRUCTIONS": "SSE4_2"},
                                   {"ONEDNN_MAX_CPU_ISA": "AVX2"},
                                   {"OPENBLAS_CORETYPE": "SkylakeX", "OPENBLAS_NUM_THREADS": "2"}])
def test_an_update_in_the_mode_does_not_follow_what_the_cpu_offers(offer):
    """One machine cannot be both vendors, but it can offer its libraries less or other: with MKL held to AVX2 or
    SSE4.2 (as on an older CPU), or OpenBLAS told to run its AVX-512 kernels on two threads, the mode's update gives
    the pinned bits, so they do not come from this CPU's widest kernels or the caller's environment."""
    from tests.algos.test_ppo import UPDATE_PINS

    assert python(UPDATE, fresh_env(True, **offer)).split() == ["reproducible", *UPDATE_PINS.values()]


# ---------------------------------------------------------------------------------------------- a training run

# Three PPO updates of the collision FlyAgent (4 envs x 4 drones, horizon 512) and the evaluation of the run's best
# checkpoint on 8 episodes, by the CLI as a user runs it; recorded on an AMD EPYC in the reproducible mode.
TRAIN_ARGS = ["configs/fly_collision.yaml", "--quiet", "--threads", "1", "--set", "sim.envs=4", "--set",
              "ppo.horizon=512", "--set", "ppo.batch_size=128", "--set", "train.max_updates=3", "--set",
              "train.max_minutes=0", "--set", "train.total_steps=0", "--set", "train.eval_every=0", "--set",
              "train.eval_episodes=8", "--set", "train.eval_envs=8", "--set", "sim.seed=5"]
TRAINING_PIN = {"weights": "7bb53886", "episodes": "21f4adac"}


def weights_hash(checkpoint: Path) -> str:
    state = torch.load(checkpoint, map_location="cpu", weights_only=False)["agent"]
    h = hashlib.sha256()
    for part in ("net", "net_average"):
        for key, value in sorted(state.get(part, {}).items()):
            h.update(key.encode())
            h.update(value.detach().contiguous().numpy().tobytes())
    return h.hexdigest()[:8]


def episodes_hash(run: Path) -> str:
    with open(run / "eval" / "episodes.csv") as fh:
        rows = [(r["Reward"], r["Time"], r["Failure_Reason"]) for r in csv.DictReader(fh)]
    return hashlib.sha256(repr(rows).encode()).hexdigest()[:8]


def train(tmp_path: Path, name: str, *flags: str, mode: bool = True) -> Path:
    args = [sys.executable, "-m", "roshan", "train", *TRAIN_ARGS, "--root", str(tmp_path), "--name", name, *flags]
    done = subprocess.run(args, cwd=ROOT, env=fresh_env(mode), capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    return tmp_path / name


@pytest.mark.slow
def test_a_short_training_run_is_pinned_on_every_cpu(tmp_path):
    run = train(tmp_path, "pinned")
    state = torch.load(run / "checkpoints" / "latest.pt", map_location="cpu", weights_only=False)
    (machine,) = state["machines"]
    assert (machine["mode"], machine["isa"], machine["torch_threads"], machine["from_update"]) == \
        ("reproducible", "AVX2", 1, 0)
    summary = json.loads((run / "eval" / "summary.json").read_text())
    assert {"weights": weights_hash(run / "checkpoints" / "latest.pt"), "episodes": episodes_hash(run)} == \
        TRAINING_PIN, summary


@pytest.mark.slow
def test_no_reproducible_trains_with_the_cpus_own_kernels_and_records_it(tmp_path):
    run = train(tmp_path, "vendor", "--no-reproducible", "--no-eval", mode=True)
    state = torch.load(run / "checkpoints" / "latest.pt", map_location="cpu", weights_only=False)
    (machine,) = state["machines"]
    assert machine["mode"] == "vendor"  # the flag wins over the mode's variables inherited from a parent process
    # the CPU's widest kernels round otherwise: the pinned run, trained with them, ends with other weights
    assert weights_hash(run / "checkpoints" / "latest.pt") != TRAINING_PIN["weights"]
