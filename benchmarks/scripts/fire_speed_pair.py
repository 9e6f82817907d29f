"""The `roshan bench fire` rows that issue 17 compares, timed with whichever roshan is on PYTHONPATH.

Run it alternately from the previous code's checkout and this one (same interpreter, same packages), e.g.

    for r in 1 2; do for tree in /path/prev /path/new; do
        PYTHONPATH=$tree python benchmarks/scripts/fire_speed_pair.py --label $tree >> pairs.jsonl; done; done

and compare the medians per row. The 941k-cell map is built here (Borkenberge tiled to Haard's 853 x 1103), so
both versions time the same map whatever their own `tiled_map` makes.
"""

import argparse
import json

import numpy as np

from roshan.maps import LandCoverMap, load_map
from roshan.runtime import init_taichi
from roshan.tools.bench import time_fire


def haard_sized(name: str = "Borkenberge", shape=(853, 1103)) -> LandCoverMap:
    base = load_map(name)
    a = base.classes
    reps_r, reps_c = -(-shape[0] // a.shape[0]), -(-shape[1] // a.shape[1])
    row = np.concatenate([a if k % 2 == 0 else a[:, ::-1] for k in range(reps_c)], axis=1)
    grid = np.concatenate([row if k % 2 == 0 else row[::-1] for k in range(reps_r)], axis=0)
    return LandCoverMap(name=f"{name}_941k", classes=np.ascontiguousarray(grid[: shape[0], : shape[1]]),
                        cell_size=base.cell_size, crs=base.crs, transform=None, source=None)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--label", required=True)
    parser.add_argument("--steps", type=int, default=50_000, help="updates per row at E = 1")
    parser.add_argument("--batch-steps", type=int, default=5_000, help="updates per row at E = 1024")
    parser.add_argument("--threads", type=int, default=None)
    args = parser.parse_args()
    init_taichi("cpu", args.threads)
    woods = load_map("35x36_Woods")
    rows = [(woods, 0.015, 1, args.steps), (woods, 0.35, 1, args.steps),
            (woods, 0.015, 1024, args.batch_steps), (woods, 0.35, 1024, args.batch_steps),
            (load_map("Borkenberge"), 0.015, 1, args.steps), (haard_sized(), 0.015, 1, args.steps)]
    for land, pct, envs, steps in rows:
        r = time_fire(land, pct, envs, steps, warmup=100)
        r["label"] = args.label
        print(json.dumps(r), flush=True)


if __name__ == "__main__":
    main()
