# The two steps of a screening run, sourced by screen.sh and screen-teachers.sh (which set PYTHON, OUT
# and ENV_ID): train, resuming from the latest checkpoint, and evaluate the final policy once.
# Evaluation episode seeds 20000+, never the bake-off's 100000+; SCREEN_EPISODES of them (default 100).

train() {  # NAME TEACHER STEPS SEED [extra train flags...]
    local name=$1 teacher=$2 steps=$3 seed=$4 latest reached
    shift 4
    echo "$(date -u +%FT%TZ) $name: training to $steps steps"
    "$PYTHON" -m kuka_curriculum train --env "$ENV_ID" --teacher "$teacher" --seed "$seed" --total-steps "$steps" \
        --eval-episodes 20 --run-dir "$OUT/$name" --resume-if-exists "$@" >> "$OUT/$name.log" 2>&1
    # Ctrl-C ends a run cleanly at a checkpoint, and train exits 0: a run short of its steps was stopped,
    # so the driver stops too, rather than evaluate it as finished (run it again to resume).
    latest=$(find "$OUT/$name/checkpoints" -name 'step_*.pt' | sort | tail -n 1)
    reached=$((10#$(basename "$latest" .pt | tr -dc 0-9)))
    if [ "$reached" -lt "$steps" ]; then
        echo "$(date -u +%FT%TZ) $name: stopped at $reached of $steps steps; run this again to resume"
        exit 130
    fi
    echo "$(date -u +%FT%TZ) $name: done"
}

evaluate() {  # NAME TASK: the final policy on SCREEN_EPISODES episodes of a task, once
    local name=$1 task=$2 json="$OUT/$1/evaluation-$2.json"
    if [ ! -f "$json" ]; then
        "$PYTHON" -m kuka_curriculum evaluate "$OUT/$name" --task "$task" --episodes "${SCREEN_EPISODES:-100}" --seed 20000 --processes 2 \
            --json "$json.partial" >> "$OUT/$name.log" 2>&1
        mv "$json.partial" "$json"
    fi
    echo "$(date -u +%FT%TZ) $name: $(tail -n 1 "$OUT/$name.log")"
}
