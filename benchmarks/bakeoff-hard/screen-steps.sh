# The two steps of a screening run, sourced by screen.sh and screen-teachers.sh (which set PYTHON, OUT
# and ENV_ID): train, resuming from the latest checkpoint, and evaluate the final policy once.
# Evaluation episode seeds 20000+, never the bake-off's 100000+.

train() {  # NAME TEACHER STEPS SEED [extra train flags...]
    local name=$1 teacher=$2 steps=$3 seed=$4
    shift 4
    echo "$(date -u +%FT%TZ) $name: training to $steps steps"
    "$PYTHON" -m kuka_curriculum train --env "$ENV_ID" --teacher "$teacher" --seed "$seed" --total-steps "$steps" \
        --eval-episodes 20 --run-dir "$OUT/$name" --resume-if-exists "$@" >> "$OUT/$name.log" 2>&1
    echo "$(date -u +%FT%TZ) $name: done"
}

evaluate() {  # NAME TASK: the final policy on 100 episodes of a task, once
    local name=$1 task=$2 json="$OUT/$1/evaluation-$2.json"
    if [ ! -f "$json" ]; then
        "$PYTHON" -m kuka_curriculum evaluate "$OUT/$name" --task "$task" --episodes 100 --seed 20000 --processes 2 \
            --json "$json.partial" >> "$OUT/$name.log" 2>&1
        mv "$json.partial" "$json"
    fi
    echo "$(date -u +%FT%TZ) $name: $(tail -n 1 "$OUT/$name.log")"
}
