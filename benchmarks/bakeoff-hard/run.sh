#!/usr/bin/env bash
# Issue 29, part 2: every teacher's bake-off on KukaGraspHard-v0 (v4). Stopped after no curriculum's
# 5 seeds: PPO alone learnt v4's hardest point on 3 of them (BENCHMARKS.md), so v4 cannot show that
# teaching decides; running this again only goes on ranking the teachers on v4. Resumable: run it again and
# finished runs are skipped, a started one continues from its latest checkpoint. It writes into
# benchmarks/bakeoff-hard/bakeoff/, which is committed as runs finish (run `$0 prune` first: it keeps
# each run's latest checkpoint only), so a later session carries on from what an earlier one landed.
#
#   setsid nohup nice -n 10 benchmarks/bakeoff-hard/run.sh > runs/bakeoff-hard.log 2>&1 &
#   benchmarks/bakeoff-hard/run.sh prune          # before committing runs
#   benchmarks/bakeoff-hard/run.sh diagnostics    # where each teacher spent its steps, finished runs so far
#
# Training seeds 0 to 4 and evaluation episode seeds 100000+, never used while screening (seeds
# 100+, evaluation seeds 20000+: screen-teachers.sh). The teachers' parameters are the ones the
# screening chose (BENCHMARKS.md, issue 29 part 2); every other setting is the bake-off's default.
# Seed 0 of every teacher, all 5 seeds of no curriculum, seeds 1 and 2 of every teacher, then seeds
# 3 and 4 of ALP-GMM and the best two, then the report over all of them.
set -euo pipefail
cd "$(dirname "$0")/../.."
PYTHON=${PYTHON:-.venv/bin/python}
OUT=benchmarks/bakeoff-hard/bakeoff
STEPS=${STEPS:-6000000}
BEST_TWO=${BEST_TWO:-}

# Every teacher in one order: the seed-0 runs of all of them come first, so a session that stops
# early still leaves one run of each; no curriculum and the teachers that did best in the screening
# lead, so the comparison that matters most lands first.
TEACHERS=(fixed currot self-paced alp-gmm adr manual random covar-gmm riac)

if [ "${1:-}" = diagnostics ]; then
    # Where each teacher spent its steps, over its finished (evaluated) runs so far:
    # benchmarks/bakeoff-hard/diagnostics/<teacher>/ (summary.md and the plot).
    for teacher in "${TEACHERS[@]}"; do
        finished=()
        for evaluation in "$OUT"/runs/"$teacher"-seed*/evaluation.json; do
            [ -f "$evaluation" ] && finished+=("$(dirname "$evaluation")")
        done
        [ ${#finished[@]} -gt 0 ] || continue
        "$PYTHON" bench/curriculum_diagnostics.py --out "benchmarks/bakeoff-hard/diagnostics/$teacher" "${finished[@]}"
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
    "$PYTHON" -m kuka_curriculum bakeoff --env KukaGraspHard-v0 --total-steps "$STEPS" --curve-episodes 20 \
        --eval-seed 100000 --out "$OUT" \
        --teacher-param currot.start=easiest --teacher-param currot.target=hardest \
        --teacher-param self-paced.kl_limit=1.0 --teacher-param self-paced.update_every=50 \
        "$@"
}
bakeoff --teachers "${TEACHERS[@]}" --seeds 1
# No curriculum's five seeds before the other rounds: its seed 1 learnt the hardest point alone (77%),
# so whether it stays under the issue's 20% over 5 seeds at this budget decides whether the
# remaining rounds run on this task at all (a no-curriculum run is also the cheapest, about 20 min).
bakeoff --teachers fixed --seeds 5
for seeds in 2 3; do
    bakeoff --teachers "${TEACHERS[@]}" --seeds "$seeds"
done
if [ -n "$BEST_TWO" ]; then
    # shellcheck disable=SC2086  # two teacher names
    bakeoff --teachers fixed alp-gmm $BEST_TWO --seeds 5
fi
bakeoff --teachers "${TEACHERS[@]}" --seeds 3
