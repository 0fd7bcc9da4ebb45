#!/usr/bin/env bash
# The full toy run of issue 28 (about 3 h on 2 cores, two runs at a time): every teacher kind and
# teachDeepRL's references, 5 seeds, 2 and 6 dimensions, 20,000 episodes. Resumable: run it again to
# go on; it skips the runs already in runs.jsonl. Stop it with SIGTERM to the driver, not SIGKILL:
# pkill -TERM -f bench/teacher_toy.py
# Parameters for the toy's rewards, which lie in [0, 1] where the KUKA defaults expect [0, 10]:
# ADR's and the self-paced teacher's reward range, CURROT's return bar, the lesson plan's threshold
# (a cube counts as mastered above 0.75); the self-paced teacher aims at the whole space. Then CURROT
# once more with its particles starting near the easiest task (uniform starts can miss the one cube
# that pays at first).
set -euo pipefail
cd "$(dirname "$0")/../.."
PYTHONPATH=. .venv/bin/python bench/teacher_toy.py --episodes 20000 --seeds 5 --spaces 2,6 --jobs 2 \
  --teacher-param 'adr.reward_range=[0,1]' \
  --teacher-param 'self-paced.reward_range=[0,1]' --teacher-param self-paced.target=uniform \
  --teacher-param currot.delta=0.5 \
  --teacher-param manual.threshold=0.75 \
  --reference ../shared/reference-teachers \
  --out benchmarks/teacher-toy/runs.jsonl --json benchmarks/teacher-toy/runs.json
PYTHONPATH=. .venv/bin/python bench/teacher_toy.py --episodes 20000 --seeds 5 --spaces 2,6 --jobs 2 --teachers currot \
  --teacher-param currot.delta=0.5 --teacher-param currot.start=easiest \
  --out benchmarks/teacher-toy/runs.jsonl --json benchmarks/teacher-toy/runs.json
