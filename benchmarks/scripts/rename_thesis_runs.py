"""One-off (issue 30): give the thesis journal's simple-flier planner runs names that say so, so that the thesis's
own condition names can hold the runs over the collision FlyAgent.

    python benchmarks/scripts/rename_thesis_runs.py benchmarks/results/thesis/experiment.journal

Rewrites run keys, condition names and run folders in every record of the journal (an append-only JSON-lines log;
the study metadata of each earlier `experiment run` holds the keys too), into a new file that then replaces the
old one atomically. Running it twice changes nothing."""

import os
import re
import sys

RENAMES = {"P3_i5": "P3_i5_simple_flier", "greedy": "greedy_simple_flier",
           "greedy_fixed": "greedy_fixed_simple_flier"}


def rename(text: str) -> str:
    for old, new in RENAMES.items():
        text = re.sub(rf'(?<=["/]){old}/seed_', f"{new}/seed_", text)  # run keys and run folders
        text = re.sub(rf'("condition": ?"){old}"', rf'\g<1>{new}"', text)
    return text


def main(path: str) -> None:
    with open(path, encoding="utf-8") as f:
        old = f.read()
    new = rename(old)
    tmp = path + ".renaming"
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(new)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    print(f"{path}: {sum(old.count(f'{k}/seed_') for k in RENAMES)} key occurrences before, "
          f"{'changed' if new != old else 'unchanged'}")


if __name__ == "__main__":
    main(sys.argv[1])
