#!/usr/bin/env bash
# Issue 59, item 1: every teacher kind on KukaGraspHard-v1 with today's student, resumable: run it again
# and finished runs are skipped, a started one continues from its latest checkpoint; each finished run
# is archived by `bakeoff` (the evaluation, the final checkpoint evaluation-only, the metrics cut to what
# the write-up reads), so its directory can be committed as it lands. Writes into
# benchmarks/bakeoff-hard/bakeoff-issue59/.
#
#   setsid nohup nice -n 10 benchmarks/bakeoff-hard/run-issue59.sh > runs/bakeoff-issue59.log 2>&1 &
#
# The same settings rule as the issue-44 rerun (docs/results/bakeoff-hard.md): the world-offset student
# for every teacher; CURROT from the easiest point towards the box target with `shaping` free and its
# recent estimate (train's KUKA registration); self-paced as the v1 screening chose; every other kind
# with the parameters train registers for KUKA. 6M steps a run, as before (the issue allows 10M: the
# budget is one of item 2's levers, screened on seeds 100+ before it changes here). In-run evaluations
# play the stratified hardest-point seeds (TrainConfig.eval_seeds, issue 59 item 3), so the steps to 80%
# read off them are comparable with the final figures; the final evaluation plays 500 hardest-point
# episodes from seed 100000. Order: seeds 0 to 2 of the five kinds the issue-44 rerun left out, then of
# the five it ran (their earlier runs played the easier consecutive in-run seeds), then seeds 3 and 4 of
# the top three (TOP_THREE, named from the 3-seed table), then the report over every kind (its table counts
# the top three's further seeds). No curriculum keeps 3 seeds, enough to hold it to the issue's bar (20% or less).
set -euo pipefail
cd "$(dirname "$0")/../.."
PYTHON=${PYTHON:-.venv/bin/python}
OUT=benchmarks/bakeoff-hard/bakeoff-issue59
LEFT_OUT=(adr random riac covar-gmm manual)
RERUN=(fixed currot self-paced alp-gmm learnability)
TOP_THREE=${TOP_THREE:-}
bakeoff() {
    local seeds=$1 && shift
    "$PYTHON" -m kuka_curriculum bakeoff --env KukaGraspHard-v1 --teachers "$@" --seeds "$seeds" \
        --total-steps 6000000 --curve-episodes 20 --eval-episodes 500 --eval-seed 100000 --out "$OUT" \
        --teacher-param currot.start=easiest --teacher-param currot.target=box \
        --teacher-param 'currot.target_box={"shaping": [0, 1]}' \
        --teacher-param self-paced.kl_limit=1.0 --teacher-param self-paced.update_every=50 \
        --ppo world_block_offset=true
}
for seeds in 1 2 3; do
    bakeoff "$seeds" "${LEFT_OUT[@]}"
done
for seeds in 1 2 3; do
    bakeoff "$seeds" "${RERUN[@]}"
done
if [ -n "$TOP_THREE" ]; then
    # shellcheck disable=SC2086  # three teacher names
    bakeoff 5 $TOP_THREE
    bakeoff 3 "${LEFT_OUT[@]}" "${RERUN[@]}"
fi
