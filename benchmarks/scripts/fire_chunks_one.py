"""One env's chunked update (`fire.parallel: chunks`), timed with whichever roshan is on PYTHONPATH: for pairing a
change to `roshan/kernels/fire_parallel.py` against the code before it, one process per timing, e.g.

    for r in 1 2 3; do for tree in /path/prev /path/new; do
        (cd $tree && PYTHONPATH=$tree python /path/new/benchmarks/scripts/fire_chunks_one.py $tree 2 941k 0.35 300) \
            >> pairs.jsonl; done; done

Arguments: label, threads, map (a shipped map's name or 941k), ignition fraction, updates per timing. Prints one
JSON line: three timings of that many updates after a reset and 200 untimed updates.
"""

import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from fire_speed_pair import haard_sized  # noqa: E402

from roshan.config import FireConfig, IgnitionConfig, WindConfig  # noqa: E402
from roshan.kernels.fire import FireSim  # noqa: E402
from roshan.maps import load_map  # noqa: E402
from roshan.runtime import init_taichi  # noqa: E402


def main() -> None:
    label, threads, name, pct, steps = sys.argv[1], int(sys.argv[2]), sys.argv[3], float(sys.argv[4]), int(sys.argv[5])
    init_taichi("cpu", threads)
    land = haard_sized() if name == "941k" else load_map(name)
    sim = FireSim(land, FireConfig(parallel="chunks"), WindConfig(), IgnitionConfig(fire_percentage=pct),
                  num_envs=1, seed=0)
    sim.reset(); sim.step(50); sim.stats()  # compiles  # noqa: E702
    sim.reset(); sim.step(200); sim.stats()  # noqa: E702
    rates = []
    for _ in range(3):
        t = time.perf_counter()
        sim.step(steps)
        sim.stats()
        rates.append(steps / (time.perf_counter() - t))
    print(json.dumps({"label": label, "map": name, "pct": pct, "threads": threads, "steps_per_s": rates,
                      "burning": int(sim.stats()["burning"][0])}), flush=True)


if __name__ == "__main__":
    main()
