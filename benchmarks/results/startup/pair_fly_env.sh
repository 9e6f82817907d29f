#!/bin/bash
# FlyVectorEnv at E = 1 (5 rounds) and roshan bench fire at E = 64, 256 (3 rounds), OLD and NEW alternating.
OLD=$1; NEW=$2
for r in 1 2 3 4 5; do
  for side in old new; do
    R=$OLD; [ $side = new ] && R=$NEW
    PY=$(dirname "$R")/python
    us=$(cd /tmp && $PY /work/main/benchmarks/results/startup/fly_env_step.py 2>/dev/null | tail -1)
    echo "{\"round\": $r, \"side\": \"$side\", \"fly_env_e1_us_per_step\": $us}"
    if [ $r -le 3 ]; then
      (cd /tmp && $R bench fire --envs 64,256 --steps 2000 --no-big --json /tmp/bf_${side}_$r.json > /dev/null 2>&1)
      $PY -c "import json,sys; d=json.load(open('/tmp/bf_${side}_$r.json')); rows=d['runs']; [print(json.dumps({'round': $r, 'side': '$side', 'envs': x['envs'], 'fire_percentage': x.get('fire_percentage', x.get('ignition')), 'env_steps_per_s': x['env_steps_per_s']})) for x in rows]" 2>&1 | head -8
    fi
  done
done
