#!/usr/bin/env bash
# Issue 29, part 2: screening no curriculum and teacher parameters on a hard family before the
# bake-off, on the screening seeds (100+) and evaluation episode seeds 20000+, never the bake-off's
# (training seeds 0 to 4, evaluation seeds 100000+). One run at a time (a run uses both cores).
#
# The configurations are the lines of a list beside this file: NAME TEACHER STEPS SEED [train flags...];
# screen-teachers.txt for KukaGraspHard-v0 (its design v4), screen-hard-v1.txt for KukaGraspHard-v1.
# The list is read again before each run, so lines can be added while this runs; every line ever run
# stays in it (the record of every configuration tried). A finished run is
# skipped, an unfinished one resumes from its checkpoint, so running this again carries on.
# Each finished run's metrics (xz-compressed since issue 44's runs, cut to the fields the write-ups read
# since 2026-12-04; earlier runs also kept the teacher database, now left in the run directory) and final
# evaluation are copied to screening/v4-NAME/ (v0) or screening/hard-v1-NAME/ (v1) beside this file.
#
#   mkdir -p runs/hard-screen-v4 && setsid nohup nice -n 10 benchmarks/bakeoff-hard/screen-teachers.sh > runs/hard-screen-v4/teachers.log 2>&1 &
#   mkdir -p runs/hard-screen-v1 && ENV_ID=KukaGraspHard-v1 setsid nohup nice -n 10 benchmarks/bakeoff-hard/screen-teachers.sh > runs/hard-screen-v1/teachers.log 2>&1 &
#
# Variables: ENV_ID (KukaGraspHard-v0, the default, or KukaGraspHard-v1), LIST (another list of lines, such as
# issue 80's screen-i80.txt, whose runs are kept under the same prefix), PYTHON (default .venv/bin/python),
# OUT (default runs/hard-screen-v4 or runs/hard-screen-v1), SCREEN_EPISODES (the final evaluation's episodes,
# default 100; issue 59's lines in screen-hard-v1.txt take 500), AFTER_RUN (a command given each finished run's
# directory before the next run starts, so the machine does one thing at a time: issue 80's validated policy,
# AFTER_RUN=".venv/bin/python bench/select_checkpoint.py --out benchmarks/bakeoff-hard/screening/i80-validated").
set -euo pipefail
cd "$(dirname "$0")/../.."
PYTHON=${PYTHON:-.venv/bin/python}
HERE=benchmarks/bakeoff-hard
ENV_ID=${ENV_ID:-KukaGraspHard-v0}
case "$ENV_ID" in
    KukaGraspHard-v0) LIST=${LIST:-$HERE/screen-teachers.txt} PREFIX=v4 OUT=${OUT:-runs/hard-screen-v4} ;;
    KukaGraspHard-v1) LIST=${LIST:-$HERE/screen-hard-v1.txt} PREFIX=hard-v1 OUT=${OUT:-runs/hard-screen-v1} ;;
    *) echo "ENV_ID must be KukaGraspHard-v0 or KukaGraspHard-v1, got $ENV_ID" >&2 && exit 2 ;;
esac
mkdir -p "$OUT"
# shellcheck source=benchmarks/bakeoff-hard/screen-steps.sh
source "$HERE/screen-steps.sh"

finished() {  # NAME: whether the run's results are copied (plain, or xz-compressed as git keeps them, so a fresh
    # checkout of committed results skips the run rather than training it again)
    local kept="$HERE/screening/$PREFIX-$1/evaluation-hardest.json"
    [ -f "$kept" ] || [ -f "$kept.xz" ]
}

next_configuration() {  # the first line of the list whose results are not yet copied
    local name
    while read -r name rest; do
        case "$name" in '' | '#'*) continue ;; esac
        if ! finished "$name"; then
            echo "$name $rest"
            return
        fi
    done < "$LIST"
}

after_run() {  # RUN_DIR: AFTER_RUN on a finished run, if set
    if [ -n "${AFTER_RUN:-}" ]; then
        echo "$(date -u +%FT%TZ) $(basename "$1"): $AFTER_RUN"
        # shellcheck disable=SC2086  # the command is words to split
        $AFTER_RUN "$1" >> "$1.log" 2>&1
    fi
}

# Runs finished before this invocation get AFTER_RUN too (a command that skips what it has done, as
# bench/select_checkpoint.py does, makes this cheap), so a screen stopped between a run and its AFTER_RUN
# loses nothing.
while read -r name rest; do
    case "$name" in '' | '#'*) continue ;; esac
    if finished "$name" && [ -d "$OUT/$name" ]; then
        after_run "$OUT/$name"
    fi
done < "$LIST"

while line=$(next_configuration) && [ -n "$line" ]; do
    read -r name teacher steps seed flags <<< "$line"
    # shellcheck disable=SC2086  # the flags are words to split
    train "$name" "$teacher" "$steps" "$seed" $flags
    evaluate "$name" hardest
    kept="$HERE/screening/$PREFIX-$name"
    mkdir -p "$kept"
    # git keeps the metrics the write-ups read (WRITE_UP_METRICS); the full log stays beside it, git-ignored
    cp "$OUT/$name/metrics.jsonl" "$kept/"
    "$PYTHON" -c 'import sys; from pathlib import Path; from learner.experiments.run_archive import thin_metrics; thin_metrics(Path(sys.argv[1]))' "$kept/metrics.jsonl"
    cp "$OUT/$name/evaluation-hardest.json" "$kept/"
    after_run "$OUT/$name"
done
echo "$(date -u +%FT%TZ) every configuration in $LIST is done"
