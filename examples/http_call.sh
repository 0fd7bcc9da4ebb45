# Sourced by the curl examples: `call`, one request to the teacher service with curl, carrying
# $KC_TEACHER_TOKEN as a bearer token when it is set; an HTTP error ends the script with the
# service's explanation on stderr.
auth=()
if [[ -n "${KC_TEACHER_TOKEN:-}" ]]; then
    auth=(-H "Authorization: Bearer $KC_TEACHER_TOKEN")
fi

call() {
    local body
    if ! body=$(curl --silent --show-error --fail-with-body "${auth[@]}" -H "Content-Type: application/json" "$@"); then
        echo "$body" >&2
        return 1
    fi
    echo "$body"
}
