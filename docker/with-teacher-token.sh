#!/bin/sh
# Run a command of the compose stack with the teacher's write token in KC_TEACHER_TOKEN.
#
#   with-teacher-token.sh [--announce] COMMAND [ARGUMENT...]
#
# A token set in .env (KC_TEACHER_TOKEN) wins. Without one, the stack's own is used: made on the first
# start, random, kept in the `secrets` volume (/secrets/teacher-token, readable by the image's user
# alone), and read from there by every service that mounts it, so a restart or a recreated container
# keeps it. Whoever comes first makes it; a hard link publishes it whole, and only once, even when two
# services start together. If no token can be had, nothing runs (so nothing is served without one).
# --announce prints where the token comes from and how to read it, for the learner's log.
set -eu

TOKEN_FILE=${KC_TEACHER_TOKEN_FILE:-/secrets/teacher-token}  # a path of its own only in tests
announce=false
if [ "${1:-}" = "--announce" ]; then
    announce=true
    shift
fi

if [ -n "${KC_TEACHER_TOKEN:-}" ]; then
    how_to_read="it is KC_TEACHER_TOKEN in your .env"
else
    if [ ! -s "$TOKEN_FILE" ]; then
        umask 077
        draft=$(mktemp "$TOKEN_FILE.XXXXXX")
        python3 -c 'import secrets; print(secrets.token_urlsafe(32))' > "$draft"
        ln "$draft" "$TOKEN_FILE" 2>/dev/null || true  # fails only where another service was first
        rm -f "$draft"
    fi
    KC_TEACHER_TOKEN=$(cat "$TOKEN_FILE")
    [ -n "$KC_TEACHER_TOKEN" ] || { echo "$TOKEN_FILE is empty: no teacher token" >&2; exit 1; }
    export KC_TEACHER_TOKEN
    how_to_read="made on the stack's first start; read it with: docker compose exec teacher cat $TOKEN_FILE"
fi

if $announce; then
    echo "teacher token: $how_to_read"
fi
exec "$@"
