"""What two threads give on this machine for four Taichi range-for passes, beside the fire update's parallel
path (BENCHMARKS "A parallel path inside one env"): pure arithmetic (no memory traffic), and a read-modify-write
of an f64 record per listed cell, 329k cells of a 941k-cell array (the burning pass's pattern): 16-byte records
(15 MB, within the L3 cache) listed in ascending cell order and scattered, and 64-byte records (60 MB) scattered.
Each thread count runs in its own process (Taichi fixes it at init), rounds alternating; printed: the median over
rounds of each process's median pass time, and the ratio.

    python benchmarks/scripts/thread_scaling_control.py --rounds 3
"""

import argparse
import json
import statistics
import subprocess
import sys

CELLS, LISTED, ITEMS = 941_000, 329_000, 4096


def child(threads: int) -> None:
    """One process: the four passes at ``threads`` threads (Taichi kernels need a source file, not ``-c``)."""
    import time

    import numpy as np
    import taichi as ti

    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, log_level=ti.WARN, random_seed=0)
    small = ti.Vector.field(2, ti.f64, CELLS)  # 15 MB: fits this machine's 32 MB L3
    large = ti.Vector.field(8, ti.f64, CELLS)  # 60 MB: does not
    listed = ti.field(ti.i32, LISTED)
    out = ti.field(ti.f32, ITEMS)

    @ti.kernel
    def arithmetic():
        for k in range(ITEMS):
            x = ti.cast(k, ti.f32)
            for _ in range(4000):
                x = ti.sin(x) * 0.999 + 0.5
            out[k] = x

    @ti.kernel
    def records_update(records: ti.template()) -> ti.i32:
        burned = 0
        for k in range(LISTED):
            r = listed[k]
            records[r][0] = records[r][0] + 0.1
            left = records[r][1] - 0.1
            records[r][1] = left
            if left <= 0.0:
                burned += 1
        return burned

    def median_ms(kernel, passes, *args):
        kernel(*args)
        times = []
        for _ in range(passes):
            t = time.perf_counter()
            kernel(*args)
            times.append(time.perf_counter() - t)
        return 1e3 * float(np.median(times))

    cells = np.random.default_rng(0).choice(CELLS, LISTED, replace=False).astype(np.int32)
    small.fill(1e9)
    large.fill(1e9)
    print(json.dumps({"arithmetic": median_ms(arithmetic, 20)}))
    listed.from_numpy(np.sort(cells))
    print(json.dumps({"16 B, ascending": median_ms(records_update, 200, small)}))
    listed.from_numpy(cells)
    print(json.dumps({"16 B, scattered": median_ms(records_update, 200, small)}))
    print(json.dumps({"64 B, scattered": median_ms(records_update, 100, large)}), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--child", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args.child)
    times: dict[tuple[str, int], list[float]] = {}
    for _ in range(args.rounds):
        for threads in (1, 2):
            out = subprocess.run([sys.executable, __file__, "--child", str(threads)], capture_output=True, text=True,
                                 check=True).stdout
            for line in out.splitlines():
                if line.startswith("{"):
                    for name, ms in json.loads(line).items():
                        times.setdefault((name, threads), []).append(ms)
    print(f"{'pass':<22}{'1 thread ms':>14}{'2 threads ms':>14}{'ratio':>8}   per round (1t / 2t)")
    for name in ("arithmetic", "16 B, ascending", "16 B, scattered", "64 B, scattered"):
        one, two = times[name, 1], times[name, 2]
        ratio = statistics.median(one) / statistics.median(two)
        rounds = ", ".join(f"{a:.2f}/{b:.2f}" for a, b in zip(one, two, strict=True))
        print(f"{name:<22}{statistics.median(one):>14.2f}{statistics.median(two):>14.2f}{ratio:>8.2f}   {rounds}")


if __name__ == "__main__":
    main()
