#!/bin/bash
# One env, fire only, 1 thread, statistics every 100 steps (roshan simulate's own timing), and FlyVectorEnv at
# E = 1: the previous code (OLD: a roshan executable of 944262c's venv) and this one (NEW), alternating.
# Usage: one_env_pair.sh OLD_ROSHAN NEW_ROSHAN ROUNDS
OLD=$1; NEW=$2; ROUNDS=${3:-3}
for r in $(seq 1 "$ROUNDS"); do
  for side in old new; do
    R=$OLD; [ $side = new ] && R=$NEW
    for pct in 0.015 0.35; do
      rate=$($R simulate --map 35x36_Woods --envs 1 --threads 1 --every 100 --steps 100000 --seed "$r" \
             --fire-percentage $pct --quiet 2>&1 | sed -n 's/.*s: \([0-9,]*\) env-steps.*/\1/p' | tr -d ,)
      echo "{\"round\": $r, \"side\": \"$side\", \"fire_percentage\": $pct, \"env_steps_per_s\": $rate}"
    done
    PY=$(dirname "$R")/python
    us=$($PY "$(dirname "$0")/fly_env_step.py" 2>/dev/null | tail -1)
    echo "{\"round\": $r, \"side\": \"$side\", \"fly_env_e1_us_per_step\": $us}"
  done
done
