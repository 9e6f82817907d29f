"""One env of the 941k-cell map at 35 %, updates per second, for the checkouts given: each (checkout, threads,
parallel) runs in its own process (Taichi fixes the thread count at init), alternating over rounds, so two
versions of the code meet the same machine state. The figures of BENCHMARKS "Timers grouped by pass".

    python benchmarks/scripts/fire_one_env_pair.py /path/old /path/new --rounds 4 --json pairs.jsonl
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

CHILD = """
import json, sys, time
sys.path.insert(0, {scripts!r})
from fire_speed_pair import haard_sized
from roshan.config import FireConfig, IgnitionConfig, WindConfig
from roshan.kernels.fire import FireSim
from roshan.runtime import init_taichi
threads, parallel = int(sys.argv[1]), sys.argv[2]
init_taichi("cpu", threads)
sim = FireSim(haard_sized(), FireConfig(parallel=parallel), WindConfig(), IgnitionConfig(fire_percentage=0.35),
              num_envs=1, seed=0)
sim.reset(); sim.step(50); sim.stats()  # compiles
sim.reset(); sim.step(200); sim.stats()
for _ in range(3):
    t = time.perf_counter(); sim.step(100); sim.stats()
    print(json.dumps({{"threads": threads, "parallel": parallel, "steps_per_s": 100 / (time.perf_counter() - t)}}))
"""
CASES = (("1", "envs"), ("1", "chunks"), ("2", "chunks"))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("trees", nargs="+", help="checkouts of roshan to compare")
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--json", default=None, help="append the timings to this jsonl file")
    args = parser.parse_args()
    scripts = str(Path(__file__).resolve().parent)
    rows = []
    for _ in range(args.rounds):
        for tree in args.trees:
            for threads, parallel in CASES:
                env = {**os.environ, "PYTHONPATH": tree}
                out = subprocess.run([sys.executable, "-c", CHILD.format(scripts=scripts), threads, parallel],
                                     capture_output=True, text=True, check=True, env=env).stdout
                rows += [{**json.loads(line), "tree": tree} for line in out.splitlines() if line.startswith("{")]
    if args.json:
        with open(args.json, "a") as f:
            f.writelines(json.dumps(r) + "\n" for r in rows)
    by = defaultdict(list)
    for r in rows:
        by[r["tree"], r["threads"], r["parallel"]].append(r["steps_per_s"])
    for (tree, threads, parallel), v in sorted(by.items()):
        print(f"{tree:<30} {parallel:>7} {threads}t  median {statistics.median(v):7.1f} updates/s "
              f"({min(v):.0f}-{max(v):.0f}, {len(v)} timings)")


if __name__ == "__main__":
    main()
