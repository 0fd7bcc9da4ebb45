#!/usr/bin/env bash
# Issue 44, item 4: the v1 bake-off again, after the teacher and student screening of 2026-11-27
# (docs/results/bakeoff-hard.md). Resumable: run it again and
# finished runs are skipped, a started one continues from its latest checkpoint; each finished run is
# archived by `bakeoff` (compressed logs, one checkpoint), so its directory can be committed as it lands.
#
#   setsid nohup nice -n 10 benchmarks/bakeoff-hard/run-v1-issue44.sh > runs/bakeoff-v1-issue44.log 2>&1 &
#
# The same student for every teacher, STUDENT: world-offset (the default since 2026-11-27 17:15 UTC: the
# networks also see the block's offset from the gripper in the world frame, `--ppo world_block_offset=true`,
# 85% against 66% on the screening seed; docs/results/bakeoff-hard.md) into
# bakeoff-v1-issue44-world-offset, or default (PPO's defaults, the first runs, stopped after 2 of them) into
# bakeoff-v1-issue44. CURROT as `train` registers it for KUKA (estimate=recent), from the
# easiest point, heading for CURROT_TARGET (box: every parameter at its hardest but shaping free;
# hardest: the point). Self-paced as the v1 screening chose. 6M steps a run (the issue allows 10M; the
# v1 screening's 10M run ended lower than its 6M twin). Training seeds 0 to 4; final evaluation on 100
# hardest-point episodes from seed 100000, never used while screening. Order: CURROT's five seeds first
# (the teacher the issue's 80% bar is decided on: its seed 0 led, 72%), then no curriculum's five (the
# issue's other bar, at most 20%), then seed 0 of every teacher, then seed 1 of every teacher, and so on,
# so the comparison grows evenly.
set -euo pipefail
cd "$(dirname "$0")/../.."
PYTHON=${PYTHON:-.venv/bin/python}
STUDENT=${STUDENT:-world-offset}
case "$STUDENT" in
    world-offset) OUT=benchmarks/bakeoff-hard/bakeoff-v1-issue44-world-offset && PPO=(--ppo world_block_offset=true) ;;
    default) OUT=benchmarks/bakeoff-hard/bakeoff-v1-issue44 && PPO=() ;;
    *) echo "STUDENT must be world-offset or default, got $STUDENT" >&2 && exit 2 ;;
esac
CURROT_TARGET=${CURROT_TARGET:-box}
TEACHERS=(fixed currot self-paced alp-gmm learnability)
case "$CURROT_TARGET" in
    box) CURROT=(--teacher-param currot.target=box --teacher-param 'currot.target_box={"shaping": [0, 1]}') ;;
    hardest) CURROT=(--teacher-param currot.target=hardest) ;;
    *) echo "CURROT_TARGET must be box or hardest, got $CURROT_TARGET" >&2 && exit 2 ;;
esac
bakeoff() {
    local seeds=$1 && shift
    "$PYTHON" -m kuka_curriculum bakeoff --env KukaGraspHard-v1 --teachers "$@" --seeds "$seeds" \
        --total-steps 6000000 --curve-episodes 20 --eval-seed 100000 --out "$OUT" \
        --teacher-param currot.start=easiest "${CURROT[@]}" \
        --teacher-param self-paced.kl_limit=1.0 --teacher-param self-paced.update_every=50 "${PPO[@]}"
}
bakeoff 5 currot
bakeoff 5 fixed
for seeds in 1 2 3 4 5; do
    bakeoff "$seeds" "${TEACHERS[@]}"
done
