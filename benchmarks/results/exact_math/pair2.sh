#!/bin/bash
cd /tmp/b35
for r in 1 2 3 4 5; do
  for side in base new; do
    if [ $side = base ]; then PY=/work/venv_base/bin/roshan; else PY=/work/main/.venv/bin/roshan; fi
    $PY bench fire --envs 1 --steps 200000 --no-big --threads 1 --json f1_${side}_$r.json > /dev/null 2>&1
    $PY bench fire --envs 1024 --steps 5000 --no-big --threads 2 --json f1024_${side}_$r.json > /dev/null 2>&1
    $PY bench env --envs 1,1024 --fire 0.015,0.35 --policies random --min-env-steps 200000 --threads 2 --json e_${side}_$r.json > /dev/null 2>&1
  done
done
echo done > /tmp/b35/DONE2
