#!/bin/bash
# roshan bench fire at E = 64, 256 (2,000 updates, 3 rounds): BASE (1b4f2a8, before this change) and NEW alternating.
for r in 1 2 3; do
  for side in base new; do
    R=/work/$side/.venv/bin/roshan; [ $side = new ] && R=/work/main/.venv/bin/roshan
    (cd /tmp && $R bench fire --envs 64,256 --steps 2000 --no-big --json /tmp/bf_${side}_$r.json > /dev/null 2>&1)
    python3 -c "import json; d=json.load(open('/tmp/bf_${side}_$r.json')); [print(json.dumps({'round': $r, 'side': '$side', 'envs': x['envs'], 'fire_percentage': x['fire_percentage'], 'env_steps_per_s': round(x['env_steps_per_s'])})) for x in d['runs']]"
  done
done
