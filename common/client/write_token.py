"""The shared write token (``KC_TEACHER_TOKEN``): which values may guard a teacher service.

The service refuses to start with a token anyone could guess, and ``train`` refuses to start a run
with one, both with the same message, so a placeholder copied from an example never goes live.
"""

from __future__ import annotations

TOKEN_VARIABLE = "KC_TEACHER_TOKEN"
MIN_TOKEN_LENGTH = 16
PLACEHOLDER_TOKENS = frozenset({"change-me", "changeme"})
"""Example values that documentation once showed; every reader of it knows them."""
MAKE_A_TOKEN = 'python3 -c "import secrets; print(secrets.token_urlsafe(32))"'


def token_problem(token: str) -> str | None:
    """Why ``token`` cannot guard the service (without repeating it), or None when it can."""
    if token.strip().lower() in PLACEHOLDER_TOKENS:
        problem = f"{TOKEN_VARIABLE} is the placeholder from .env.example, which anyone can guess"
    elif len(token) < MIN_TOKEN_LENGTH:
        problem = f"{TOKEN_VARIABLE} has {len(token)} characters, too few to be secret (at least {MIN_TOKEN_LENGTH})"
    else:
        return None
    return f"{problem}; set it to a random one, e.g. the output of: {MAKE_A_TOKEN}"


def check_token(token: str) -> str:
    """``token``, or ``ValueError`` saying why it cannot be used and how to make one."""
    problem = token_problem(token)
    if problem is not None:
        raise ValueError(problem)
    return token
