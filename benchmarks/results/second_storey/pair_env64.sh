#!/bin/bash
# roshan bench env at E = 64 (random actions, 40,000 env steps), previous code (a worktree at PREV_TREE, default
# /work/exp: 9d2c47c on 2026-12-04) and this code alternating,
# 6 rounds; one JSON line per row.
PY=/work/main/.venv/bin/python
for r in 1 2 3 4 5 6; do
  for side in prev new; do
    tree=/work/main; [ $side = prev ] && tree=${PREV_TREE:-/work/exp}
    (cd /tmp && PYTHONPATH=$tree $PY -m roshan bench env --envs 64 --drones 4 --fire 0.015,0.35 --policies random --min-env-steps 40000 --json /tmp/be64_${side}_$r.json > /dev/null 2>&1)
    $PY -c "import json; d=json.load(open('/tmp/be64_${side}_$r.json')); [print(json.dumps({'bench': 'env', 'round': $r, 'side': '$side', 'envs': x['envs'], 'fire_percentage': x['fire_percentage'], 'env_steps_per_s': round(x['env_steps_per_s'])})) for x in d['runs']]"
  done
done
