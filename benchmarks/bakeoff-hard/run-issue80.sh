#!/usr/bin/env bash
# Issue 80, item 4: the recipe's 10-seed proof (docs/results/student.md, "The recipe's proof", written before
# any of its runs). CURROT with `--config hard-grasp-v1` on seeds 0 to 9, then no curriculum (`fixed`) with the
# same student and budget on seeds 0 to 2, each run's validated policy scored on the 500 hardest-point episodes
# from seed 100000. Resumable: run it again and finished runs are skipped, a started one continues from its
# latest checkpoint; each finished run is archived by `bakeoff`, so its directory can be committed as it lands.
#
#   setsid nohup nice -n 10 benchmarks/bakeoff-hard/run-issue80.sh 2 > runs/bakeoff-issue80.log 2>&1 &
#
# The argument is how many of CURROT's seeds to have trained when it stops (default 10, then no curriculum's
# three): a session starts only the runs it can finish.
set -euo pipefail
cd "$(dirname "$0")/../.."
PYTHON=${PYTHON:-.venv/bin/python}
CURROT_SEEDS=${1:-10}
bakeoff() {
    "$PYTHON" -m kuka_curriculum bakeoff --config hard-grasp-v1 --eval-episodes 500 --eval-seed 100000 \
        --curve-episodes 20 --out benchmarks/bakeoff-hard/bakeoff-issue80 "$@"
}
bakeoff --teachers currot --seeds "$CURROT_SEEDS"
if [ "$CURROT_SEEDS" -ge 10 ]; then
    bakeoff --teachers currot fixed --seeds 3  # the report counts CURROT's further seeds
fi
