#!/bin/bash
# Paired before/after benchmark: the commit before the redesign (/work/base, f14bffa) and the new code (/work/main),
# alternating, two rounds each, same interpreter and packages.
set -u
out=/tmp/bench/res; mkdir -p $out
for round in 1 2; do
  for side in before after; do
    dir=/work/base; [ $side = after ] && dir=/work/main
    (cd $dir && python -m roshan bench fire --envs 1,1024 --steps 5000 --big --json $out/fire_${side}_$round.json > $out/fire_${side}_$round.txt 2>&1)
    (cd $dir && python -m roshan bench env --envs 64,1024 --fire 0.015,0.35 --policies random,simple,fly_collision --min-env-steps 100000 --json $out/env_${side}_$round.json > $out/env_${side}_$round.txt 2>&1)
    echo "$(date +%T) $side $round done"
  done
done
