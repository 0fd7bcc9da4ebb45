#!/usr/bin/env bash
# Levels over HTTP with curl and jq: robust PLR over 200 level seeds. Each task says whether its
# episode is for scoring only (play it and report it, but leave it out of the update); each result
# may carry a score, the learner's positive value loss (the mean over its steps of max(GAE advantage, 0)).
#
#   .venv/bin/kuka-curriculum serve --port 8000 &
#   bash examples/http_levels.sh [TEACHER_URL [CURRICULUM]]
#
# Writes carry $KC_TEACHER_TOKEN as a bearer token when it is set.
set -euo pipefail

url="${1:-http://127.0.0.1:8000}"
curriculum="${2:-shell-levels}"
api="$url/api/v1/curricula/$curriculum"
source "$(dirname "${BASH_SOURCE[0]}")/http_call.sh"  # call: one request, with the token if set

echo "1. register: robust PLR over one integer parameter, the level seed 0 to 199"
call -X PUT "$api" -d '{
    "teacher": "plr",
    "space": [{"name": "level", "type": "integer", "low": 0, "high": 199}],
    "params": {"robust": true},
    "seed": 0
}' | jq -c '{name, teacher: .config.teacher, space: .config.space}'

echo "2. five rounds of 40 tasks, each result scored (here made up: the higher the level, the more it teaches)"
for round in 1 2 3 4 5; do
    tasks=$(call -X POST "$api/tasks" -d '{"count": 40}')
    jq -c --arg round "$round" '{round: ($round | tonumber), score_only: ([.tasks[] | select(.score_only)] | length),
        trained: ([.tasks[] | select(.score_only | not)] | length)}' <<<"$tasks"
    results=$(jq -c '{results: [.tasks[] | {task_id, reward: 1.0, success: true,
        score: (.params.level / 199)}]}' <<<"$tasks")
    call -X POST "$api/results" -d "$results" >/dev/null
done

echo "3. the likeliest next levels, as the dashboard shows them"
call "$api/state?recent=1" | jq -c '{scored_levels: .teacher.scored_levels, replay_chance: .teacher.replay_chance,
    likeliest: [.teacher.levels[:5][] | {level, probability: (.probability * 1000 | round / 1000), score}]}'
