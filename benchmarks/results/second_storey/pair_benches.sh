#!/bin/bash
# roshan bench fire (E = 1, 64; 3,000 updates) and roshan bench env (E = 1, 64; random actions), alternating the
# previous code (a worktree at PREV_TREE, default /work/exp: 9d2c47c on 2026-12-04, c638f97 = 89bf684^ on
# 2026-12-06 for benches_energy_2026-12-06.jsonl; run with PYTHONPATH) and this code, 3 rounds; one JSON line per row.
PY=/work/main/.venv/bin/python
for r in 1 2 3; do
  for side in prev new; do
    tree=/work/main; [ $side = prev ] && tree=${PREV_TREE:-/work/exp}
    (cd /tmp && PYTHONPATH=$tree $PY -m roshan bench fire --envs 1,64 --steps 3000 --warmup 100 --no-big --json /tmp/bf_${side}_$r.json > /dev/null 2>&1)
    $PY -c "import json; d=json.load(open('/tmp/bf_${side}_$r.json')); [print(json.dumps({'bench': 'fire', 'round': $r, 'side': '$side', 'envs': x['envs'], 'fire_percentage': x['fire_percentage'], 'env_steps_per_s': round(x['env_steps_per_s'])})) for x in d['runs']]"
    (cd /tmp && PYTHONPATH=$tree $PY -m roshan bench env --envs 1,64 --drones 4 --fire 0.015,0.35 --policies random --min-env-steps 20000 --json /tmp/be_${side}_$r.json > /dev/null 2>&1)
    $PY -c "import json; d=json.load(open('/tmp/be_${side}_$r.json')); [print(json.dumps({'bench': 'env', 'round': $r, 'side': '$side', 'envs': x['envs'], 'fire_percentage': x['fire_percentage'], 'env_steps_per_s': round(x['env_steps_per_s'])})) for x in d['runs']]"
  done
done
