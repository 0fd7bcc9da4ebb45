#!/usr/bin/env bash
# Issue 79's level side-by-side, the plan written in docs/results/levels.md ("Plan (written before the runs)"),
# run unattended: every arm on seeds 0 to 19, then the throughput rounds, then the summary.
#
#     setsid nohup benchmarks/levels-minigrid/gamut-200/run.sh > /dev/null 2>&1 &
#
# bench/levels_side_by_side.py skips a finished run and resumes an unfinished one, so this script only starts it
# again after a failure (a crashed Ray worker, a teacher service that would not start), up to TRIES times,
# and the whole plan can be stopped (kill the script's process group) and started again at any time. Everything
# it prints goes to $OUT/plan.log (git-ignored). The throughput rounds time the machine: leave it to itself then.
set -u
cd "$(dirname "$0")/../../.."

OUT=${OUT:-benchmarks/levels-minigrid/gamut-200}
SEEDS=${SEEDS:-$(seq -s ' ' 0 19)}
# The plan's settings, spelled out so that a later change of the driver's defaults does not change the plan.
SETTINGS=(--env MiniGrid-Gamut-v0 --levels 200 --steps 500000 --eval-every 25 --eval-episodes 40
          --test-levels 200 --test-repeats 2 --take-off 0.5)
THROUGHPUT_SETTINGS=(--throughput --throughput-steps 400000 --throughput-window 0.5 --rounds 5)
TRIES=${TRIES:-5}
THROUGHPUT=${THROUGHPUT:-1}
LOG="$OUT/plan.log"
mkdir -p "$OUT"

run_until_done() {
    local try
    for try in $(seq 1 "$TRIES"); do
        echo "$(date -u +%FT%TZ) try $try: $*" >> "$LOG"
        nice -n 5 .venv/bin/python bench/levels_side_by_side.py --out "$OUT" "${SETTINGS[@]}" "$@" >> "$LOG" 2>&1
        local status=$?
        [ "$status" = 0 ] && return 0
        echo "$(date -u +%FT%TZ) failed (exit $status); starting again in a minute" >> "$LOG"
        sleep 60
    done
    echo "$(date -u +%FT%TZ) gave up after $TRIES tries: $*" >> "$LOG"
    return 1
}

# shellcheck disable=SC2086  # the seeds are words
run_until_done --seeds $SEEDS || exit 1
if [ "$THROUGHPUT" = 1 ]; then
    run_until_done "${THROUGHPUT_SETTINGS[@]}" || exit 1
fi
.venv/bin/python bench/levels_side_by_side.py --out "$OUT" "${SETTINGS[@]}" --summarise >> "$LOG" 2>&1
echo "$(date -u +%FT%TZ) the plan is done: $OUT/results.md" >> "$LOG"
