#!/bin/bash
# The sight gap of a policy: its greedy episodes in the real world, and its greedy plans made on the
# world model's frames and executed for real, on the same 20 scenes per MT10 task; then its real
# success on the ladder's 50 evaluation seeds per task.
cd /work/main
G=.venv/bin/gymnast
name=$1; policy=$2
out=runs/sight/$name
mkdir -p $out
$G collect --policy $policy --temperature 0 --tasks mt10 --episodes-per-task 20 --noise 0 --failure-fraction 0 \
  --first-seed 7000 --cameras front,gripper --workers 2 --out $out/real > $out/real.log 2>&1
$G collect --policy $policy --temperature 0 --imagine-with results/headline/world_model --tasks mt10 \
  --episodes-per-task 20 --noise 0 --failure-fraction 0 --first-seed 7000 --cameras front,gripper --workers 2 \
  --out $out/planned > $out/planned.log 2>&1
$G eval --policy $policy --tasks mt10 --episodes 50 --workers 2 --videos-per-task 0 --out $out/eval.json > $out/eval.log 2>&1
