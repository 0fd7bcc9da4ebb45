#!/usr/bin/env bash
# The teacher service's HTTP API from the shell, with curl (and jq to read the answers):
# list the teacher kinds, register a curriculum, take tasks, post their results, read the teacher's state.
#
#   .venv/bin/kuka-curriculum serve --port 8000 &
#   bash examples/http_api.sh [TEACHER_URL [CURRICULUM]]
#
# Writes (PUT and POST) carry $KC_TEACHER_TOKEN as a bearer token when it is set, as the service
# requires when it was started with one; reads need none. The full API is described at TEACHER_URL/docs.
set -euo pipefail

url="${1:-http://127.0.0.1:8000}"
curriculum="${2:-shell-demo}"
api="$url/api/v1/curricula/$curriculum"
source "$(dirname "${BASH_SOURCE[0]}")/http_call.sh"  # call: one request, with the token if set

echo "watch the curriculum at $url/curricula/$curriculum"

echo "0. the teacher kinds on offer (GET /api/v1/teachers also lists each one's parameters and bounds)"
call "$url/api/v1/teachers" | jq -r '.teachers[] | "  \(.kind): \(.summary)"'

echo "1. register: ALP-GMM over a two-parameter task space (201 created, 200 if it already exists)"
call -X PUT "$api" -d '{
    "teacher": "alp-gmm",
    "space": [
        {"name": "gravity", "low": 2.0, "high": 12.0, "hardest": 12.0, "easiest": 2.0},
        {"name": "mass", "low": 0.5, "high": 1.5, "hardest": 1.5, "easiest": 0.5}
    ],
    "params": {"fit_rate": 100},
    "seed": 0
}' | jq -c '{name, teacher: .config.teacher, created_at}'

echo "2. take 3 tasks"
tasks=$(call -X POST "$api/tasks" -d '{"count": 3}')
jq -c '.tasks[]' <<<"$tasks"

echo "3. post a result per task (here a made-up return: the lower the gravity, the higher)"
results=$(jq -c '{results: [.tasks[] | {
    task_id, reward: (-10 * .params.gravity), success: (.params.gravity < 5), length: 200
}]}' <<<"$tasks")
call -X POST "$api/results" -d "$results" | jq -c .

echo "4. read the curriculum's state"
call "$api/state?recent=3" | jq -c '{counters: .curriculum.counters, teacher: .teacher.kind,
    recent: [.recent_results[] | {task_id, reward}]}'
