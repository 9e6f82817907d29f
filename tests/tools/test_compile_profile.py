"""benchmarks/compile_profile: a process started with it logs each kernel's AST transform and first launch, named
and with the running test, and the summary adds them up."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

KERNELS = """
import taichi as ti
ti.init(arch=ti.cpu, offline_cache=False, log_level=ti.ERROR)
x = ti.field(ti.f32, 4)

@ti.kernel
def twice(k: ti.template()):
    for i in x:
        x[i] = 2 * x[i] + k

twice(1)
twice(1)  # the same instance: neither transformed nor first-launched again
twice(2)  # a new instance
"""


def test_each_kernel_instance_is_logged_once_and_summed(tmp_path):
    log = tmp_path / "compile.tsv"
    env = dict(os.environ, COMPILE_PROFILE_LOG=str(log), PYTHONPATH=str(ROOT / "benchmarks" / "compile_profile"),
               PYTEST_CURRENT_TEST="tests/x.py::test_y (call)")
    script = tmp_path / "kernels.py"  # Taichi reads a kernel's source from its file
    script.write_text(KERNELS)
    subprocess.run([sys.executable, str(script)], env=env, check=True, cwd=tmp_path)
    rows = [line.split("\t") for line in log.read_text().splitlines()]
    assert [(r[1], r[2]) for r in rows if r[2] == "twice"] == [("ast", "twice"), ("launch1", "twice")] * 2
    assert {r[4] for r in rows} == {"tests/x.py::test_y"}
    summary = subprocess.run([sys.executable, str(ROOT / "benchmarks/scripts/compile_profile_summary.py"), str(log)],
                             capture_output=True, text=True, check=True).stdout
    assert "twice" in summary and "tests/x.py" in summary
