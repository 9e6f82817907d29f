"""Summarise a compile profile (benchmarks/compile_profile/sitecustomize.py): seconds of AST transforms and of first
launches in all, then the kernels and the test files that cost most.

    python benchmarks/scripts/compile_profile_summary.py /tmp/compile.tsv [--top 12]
"""

import argparse
from collections import defaultdict


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log")
    parser.add_argument("--top", type=int, default=12)
    args = parser.parse_args()
    totals: dict[str, float] = defaultdict(float)
    kernels: dict[str, list[float]] = defaultdict(list)
    files: dict[str, float] = defaultdict(float)
    with open(args.log) as f:
        for line in f:
            _pid, event, name, seconds, test = line.rstrip("\n").split("\t")
            totals[event] += float(seconds)
            if event == "launch1":
                kernels[name].append(float(seconds))
            files[test.split("::")[0]] += float(seconds)
    for event, seconds in sorted(totals.items()):
        print(f"{event}: {seconds:,.0f} s")
    print(f"\nfirst launches by kernel (top {args.top}): seconds, count, kernel")
    for name, times in sorted(kernels.items(), key=lambda kv: -sum(kv[1]))[: args.top]:
        print(f"{sum(times):8.1f} {len(times):5d}  {name}")
    print(f"\nAST transforms and first launches by test file (top {args.top}): seconds, file")
    for name, seconds in sorted(files.items(), key=lambda kv: -kv[1])[: args.top]:
        print(f"{seconds:8.1f}  {name}")


if __name__ == "__main__":
    main()
