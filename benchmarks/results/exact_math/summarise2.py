import json, statistics as st
def rows(prefix, side, n=5):
    out = {}
    for r in range(1, n + 1):
        for row in json.load(open(f"/tmp/b35/{prefix}_{side}_{r}.json"))["runs"]:
            key = (row["fire_percentage"], row["envs"], row.get("policy", "fire"))
            out.setdefault(key, []).append(row["env_steps_per_s"])
    return out
for prefix, what in (("f1", "fire, 200,000 steps, 1 thread"), ("f1024", "fire, 5,000 steps, 2 threads"),
                     ("e", "env, random actions, 200,000 env-steps, 2 threads")):
    b, n = rows(prefix, "base"), rows(prefix, "new")
    for k in b:
        rb, rn = st.median(b[k]), st.median(n[k])
        pr = sorted(y / x for x, y in zip(b[k], n[k]))
        noise = max(b[k]) / min(b[k])
        print(f"| {what} | {k[0]*100:g} % | {k[1]} | {rb:,.0f} | {rn:,.0f} | **{rn/rb:.2f}** | {st.median(pr):.2f} ({pr[0]:.2f}-{pr[-1]:.2f}) | {noise:.2f} |")
