#!/bin/bash
# paired: previous commit (venv_base, /work/base) vs this tree (.venv, /work/main), alternating, 3 rounds
cd /tmp/b35
for r in 1 2 3; do
  for side in base new; do
    if [ $side = base ]; then PY=/work/venv_base/bin/roshan; else PY=/work/main/.venv/bin/roshan; fi
    $PY bench fire --envs 1,1024 --steps 5000 --no-big --threads 2 --json fire_${side}_$r.json > fire_${side}_$r.log 2>&1
    $PY bench env --envs 1,64,1024 --fire 0.015,0.35 --policies random,collision --min-env-steps 50000 --threads 2 --json env_${side}_$r.json > env_${side}_$r.log 2>&1
  done
done
echo done > /tmp/b35/DONE
