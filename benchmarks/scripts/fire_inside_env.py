"""One env on a big map, 1 and 2 threads, with the env-serial update (`fire.parallel: envs`) and the chunked one
(`chunks`): the figures of BENCHMARKS "A parallel path inside one env". Each (threads) runs in its own process
(Taichi fixes the thread count at init); rows are updates per second after a reset and 200 untimed updates.

    python benchmarks/scripts/fire_inside_env.py --json benchmarks/results/fire_inside_env.jsonl

Two versions of the code (checkouts given as arguments) alternate round by round, so both meet the same machine
state; ``--rows 1`` keeps the first row (the 941k-cell map at 35 %):

    python benchmarks/scripts/fire_inside_env.py /path/old /path/new --rows 1 --rounds 4
"""

import argparse
import json
import os
import subprocess
import sys
import time

CHILD = """
import json, sys, time
sys.path.insert(0, {scripts!r})
from fire_speed_pair import haard_sized
from roshan.config import FireConfig, IgnitionConfig, WindConfig
from roshan.kernels.fire import FireSim
from roshan.maps import load_map
from roshan.runtime import init_taichi
threads = int(sys.argv[1]); init_taichi("cpu", threads)
for name, pct, steps in {rows!r}:
    land = haard_sized() if name == "941k" else load_map(name)
    for parallel in ("envs", "chunks"):
        sim = FireSim(land, FireConfig(parallel=parallel), WindConfig(), IgnitionConfig(fire_percentage=pct),
                      num_envs=1, seed=0)
        sim.reset(); sim.step(50); sim.stats()  # compiles
        sim.reset(); sim.step(200); sim.stats()
        t = time.perf_counter(); sim.step(steps); sim.stats(); dt = time.perf_counter() - t
        print(json.dumps({{"map": name, "fire_percentage": pct, "threads": threads, "parallel": parallel,
                          "layout": sim.layout, "steps": steps, "steps_per_s": steps / dt,
                          "burning": int(sim.stats()["burning"][0])}}), flush=True)
"""

ROWS = [("941k", 0.35, 300), ("Borkenberge", 0.35, 1000), ("941k", 0.015, 5000), ("Borkenberge", 0.015, 10000)]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("trees", nargs="*", help="checkouts to compare (default: the roshan on PYTHONPATH)")
    parser.add_argument("--json", default=None, help="append the rows to this jsonl file")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--rows", type=int, default=len(ROWS), help="time only the first N rows")
    args = parser.parse_args()
    scripts = sys.path[0]
    chosen = ROWS[: args.rows]
    rows = []
    for _ in range(args.rounds):
        for tree in args.trees or [None]:
            env = {**os.environ, "PYTHONPATH": tree} if tree else None
            for threads in (1, 2):
                out = subprocess.run([sys.executable, "-c", CHILD.format(scripts=scripts, rows=chosen), str(threads)],
                                     capture_output=True, text=True, check=True, env=env).stdout
                rows += [{**json.loads(line), "tree": tree} for line in out.splitlines() if line.startswith("{")]
    stamp = time.strftime("%Y-%m-%dT%H:%M:%S")
    if args.json:
        with open(args.json, "a") as f:
            for r in rows:
                f.write(json.dumps({**r, "time": stamp}) + "\n")
    best = {}
    for r in rows:
        key = (r["tree"], r["map"], r["fire_percentage"], r["parallel"], r["threads"])
        best[key] = max(best.get(key, 0.0), r["steps_per_s"])
    print(f"{'tree':<20}{'map':<12}{'ign':>6}{'envs 1t':>10}{'envs 2t':>10}{'chunks 1t':>11}{'chunks 2t':>11}"
          f"{'chunks 2t / envs 1t':>21}{'chunks 2t / 1t':>16}")
    for tree in args.trees or [None]:
        for name, pct, _ in chosen:
            v = {(p, t): best[(tree, name, pct, p, t)] for p in ("envs", "chunks") for t in (1, 2)}
            print(f"{str(tree or '-'):<20}{name:<12}{pct * 100:>5.1f}%{v['envs', 1]:>10.1f}{v['envs', 2]:>10.1f}"
                  f"{v['chunks', 1]:>11.1f}{v['chunks', 2]:>11.1f}{v['chunks', 2] / v['envs', 1]:>21.2f}"
                  f"{v['chunks', 2] / v['chunks', 1]:>16.2f}")


if __name__ == "__main__":
    main()
