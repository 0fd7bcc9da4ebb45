"""examples/http_levels.sh: robust PLR over level seeds with curl and jq, run as a user would."""

from __future__ import annotations

import json
import shutil

import pytest
from example_runner import curriculum_state, finish, start_example

pytestmark = pytest.mark.skipif(not (shutil.which("curl") and shutil.which("jq")), reason="needs curl and jq")


def test_the_script_plays_scored_levels_and_shows_the_likeliest(teacher):
    output = finish(start_example("http_levels.sh", teacher.url, "levels"), timeout=60)
    rounds = [json.loads(line) for line in output.splitlines() if line.startswith('{"round"')]
    assert [r["score_only"] + r["trained"] for r in rounds] == [40] * 5
    assert rounds[0]["score_only"] == 40, "nothing is scored yet: every first-round level is explored for a score"
    assert rounds[-1]["trained"] > 0, "once levels have scores, replays are trained on"

    summary = json.loads(output.splitlines()[-1])
    state = curriculum_state(teacher, "levels")
    assert summary["scored_levels"] == state["teacher"]["scored_levels"] > 0
    assert summary["likeliest"][0]["level"] == state["teacher"]["levels"][0]["level"]
    assert state["recent_results"][-1]["score"] is not None
