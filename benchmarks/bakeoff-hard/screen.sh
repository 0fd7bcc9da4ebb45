#!/usr/bin/env bash
# Issue 29, part 1: the screening runs that say whether KukaGraspHard-v0's hardest task is hard for PPO
# without a curriculum, and whether its easiest point is quickly learnt. One run at a time (a run uses
# both cores); each resumes from its latest checkpoint, so running this again finishes what is left.
# Training seeds 100+ and final evaluation episode seeds 20000+: the bake-off trains seeds 0 to 4 and
# evaluates on episode seeds 100000+, so none of these is reused there. The last runs, teachers with
# their KUKA defaults, are probes of whether a curriculum gets anywhere, not bake-off results.
#
#   mkdir -p runs/hard-screen-v4 && setsid nohup nice -n 10 benchmarks/bakeoff-hard/screen.sh > runs/hard-screen-v4/driver.log 2>&1 &
#
# Variables: PYTHON (default .venv/bin/python), OUT (default runs/hard-screen-v4; v3's runs are in runs/hard-screen).
set -euo pipefail
cd "$(dirname "$0")/../.."
PYTHON=${PYTHON:-.venv/bin/python}
OUT=${OUT:-runs/hard-screen-v4}
ENV_ID=KukaGraspHard-v0
EASIEST='{"rnd_obj_x":0,"rnd_obj_y":0,"rnd_obj_ang":0,"jp2":1.3,"jp4":-1.0,"bias_obj_y":0.04,"obj_far":0,"shaping":1,"move_scale":1,"align_margin":90}'
mkdir -p "$OUT"

# shellcheck source=benchmarks/bakeoff-hard/screen-steps.sh
source benchmarks/bakeoff-hard/screen-steps.sh

train fixed-hardest-seed100 fixed 3000000 100
train easiest-seed100 fixed 150000 100 --teacher-param "point=$EASIEST"
train fixed-hardest-seed101 fixed 3000000 101
evaluate easiest-seed100 easiest
evaluate fixed-hardest-seed100 hardest
evaluate fixed-hardest-seed101 hardest
# Not results for the bake-off, probes for it (part 2 screens teachers on their own seeds): does each
# teacher, with its KUKA defaults, get anywhere here? CURROT starts near the easiest task and heads
# for the hardest, as the self-paced teacher does by default.
train alp-gmm-seed100 alp-gmm 3000000 100
evaluate alp-gmm-seed100 hardest
train adr-seed100 adr 3000000 100
evaluate adr-seed100 hardest
train currot-easiest-to-hardest-seed100 currot 3000000 100 --teacher-param start=easiest --teacher-param target=hardest
evaluate currot-easiest-to-hardest-seed100 hardest
train self-paced-seed100 self-paced 3000000 100
evaluate self-paced-seed100 hardest
echo "$(date -u +%FT%TZ) all screening runs done"
