"""The table of BENCHMARKS "Same numbers on every CPU": medians of five rounds per side (pair2.sh's JSON files)."""

import json
import statistics as st
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHES = (("f1", "fire, 200,000 steps, 1 thread"), ("f1024", "fire, 5,000 steps, 2 threads"),
           ("e", "env, random actions, 200,000 env-steps, 2 threads"))


def rows(prefix: str, side: str, rounds: int = 5) -> dict[tuple, list[float]]:
    out: dict[tuple, list[float]] = {}
    for r in range(1, rounds + 1):
        for row in json.loads((HERE / f"{prefix}_{side}_{r}.json").read_text())["runs"]:
            key = (row["fire_percentage"], row["envs"], row.get("policy", "fire"))
            out.setdefault(key, []).append(row["env_steps_per_s"])
    return out


def main() -> None:
    for prefix, what in BENCHES:
        old, new = rows(prefix, "base"), rows(prefix, "new")
        for key in old:
            mo, mn = st.median(old[key]), st.median(new[key])
            paired = sorted(y / x for x, y in zip(old[key], new[key], strict=True))
            noise = max(old[key]) / min(old[key])
            print(f"| {what} | {key[0] * 100:g} % | {key[1]} | {mo:,.0f} | {mn:,.0f} | {mn / mo:.2f} | "
                  f"{st.median(paired):.2f} ({paired[0]:.2f}-{paired[-1]:.2f}) | {noise:.2f} |")


if __name__ == "__main__":
    main()
