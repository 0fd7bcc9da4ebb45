#!/usr/bin/env bash
# Issue 29, part 2: every teacher's bake-off on a hard family, resumable: run it again and finished runs
# are skipped, a started one continues from its latest checkpoint. ENV_ID picks the family:
# - KukaGraspHard-v1 (the default): writes into benchmarks/bakeoff-hard/bakeoff-v1/.
# - KukaGraspHard-v0 (its design v4): writes into benchmarks/bakeoff-hard/bakeoff/. Stopped after no
#   curriculum's 5 seeds: PPO alone learnt v0's hardest point on 3 of them (docs/results/bakeoff-hard.md), so v0 cannot
#   show that teaching decides; running it again only goes on ranking the teachers on v0.
# Outputs are committed as runs finish (run `$0 prune` first: it keeps each run's latest checkpoint
# only), so a later session carries on from what an earlier one landed.
#
#   setsid nohup nice -n 10 benchmarks/bakeoff-hard/run.sh > runs/bakeoff-hard-v1.log 2>&1 &
#   benchmarks/bakeoff-hard/run.sh prune          # before committing runs
#   benchmarks/bakeoff-hard/run.sh diagnostics    # where each teacher spent its steps, finished runs so far
#
# Training seeds 0 to 4 and evaluation episode seeds 100000+, never used while screening (seeds
# 100+, evaluation seeds 20000+: screen-teachers.sh). The teachers' parameters are the ones the
# screening chose (docs/results/bakeoff-hard.md); every other setting is the bake-off's default.
# No curriculum's 5 seeds first (whether it stays under the issue's 20% decides whether the family can
# show anything, and its runs are the cheapest, about 20 min), then seed 0 of every teacher, seeds 1
# and 2 of every teacher, seeds 3 and 4 of ALP-GMM and the best two (BEST_TWO), and the report over all.
set -euo pipefail
cd "$(dirname "$0")/../.."
PYTHON=${PYTHON:-.venv/bin/python}
ENV_ID=${ENV_ID:-KukaGraspHard-v1}
case "$ENV_ID" in
    KukaGraspHard-v0) OUT=benchmarks/bakeoff-hard/bakeoff DIAGNOSTICS=benchmarks/bakeoff-hard/diagnostics ;;
    KukaGraspHard-v1) OUT=benchmarks/bakeoff-hard/bakeoff-v1 DIAGNOSTICS=benchmarks/bakeoff-hard/diagnostics-v1 ;;
    *) echo "ENV_ID must be KukaGraspHard-v0 or KukaGraspHard-v1, got $ENV_ID" >&2 && exit 2 ;;
esac
STEPS=${STEPS:-6000000}
BEST_TWO=${BEST_TWO:-}

# Every teacher in one order: no curriculum and the teachers that did best in the screening lead, so
# the comparison that matters most lands first in each round.
TEACHERS=(fixed currot self-paced alp-gmm adr manual random covar-gmm riac)

if [ "${1:-}" = diagnostics ]; then
    # Where each teacher spent its steps, over its finished (evaluated) runs so far:
    # $DIAGNOSTICS/<teacher>/ (summary.md and the plot).
    for teacher in "${TEACHERS[@]}"; do
        finished=()
        for evaluation in "$OUT"/runs/"$teacher"-seed*/evaluation.json "$OUT"/runs/"$teacher"-seed*/evaluation.json.xz; do
            [ -f "$evaluation" ] && finished+=("$(dirname "$evaluation")")
        done
        [ ${#finished[@]} -gt 0 ] || continue
        "$PYTHON" bench/curriculum_diagnostics.py --out "$DIAGNOSTICS/$teacher" "${finished[@]}"
    done
    exit 0
fi

if [ "${1:-}" = prune ]; then
    for checkpoints in "$OUT"/runs/*/checkpoints; do
        [ -d "$checkpoints" ] || continue
        find "$checkpoints" -name 'step_*.pt' | sort | head -n -1 | xargs -r rm --
    done
    exit 0
fi

bakeoff() {
    "$PYTHON" -m kuka_curriculum bakeoff --env "$ENV_ID" --total-steps "$STEPS" --curve-episodes 20 \
        --eval-seed 100000 --out "$OUT" \
        --teacher-param currot.start=easiest --teacher-param currot.target=hardest \
        --teacher-param self-paced.kl_limit=1.0 --teacher-param self-paced.update_every=50 \
        "$@"
}
bakeoff --teachers fixed --seeds 5
bakeoff --teachers "${TEACHERS[@]}" --seeds 1
for seeds in 2 3; do
    bakeoff --teachers "${TEACHERS[@]}" --seeds "$seeds"
done
if [ -n "$BEST_TWO" ]; then
    # shellcheck disable=SC2086  # two teacher names
    bakeoff --teachers fixed alp-gmm $BEST_TWO --seeds 5
fi
bakeoff --teachers "${TEACHERS[@]}" --seeds 3
