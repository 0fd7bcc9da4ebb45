import json
import math

from learner.core.json_file import dumps, write_json


def test_lists_of_numbers_take_one_line_and_everything_reads_back_unchanged(tmp_path):
    data = {
        "column": [1, -2.5, 3e-07, True, None],
        "infinite": [math.inf, -math.inf],
        "names": ["a", "b"],
        "looks_like_a_list": "[1,\n2]",
        "nested": {"rows": [[1, 2], [3]], "empty": []},
    }
    text = dumps(data)
    assert '"column": [1, -2.5, 3e-07, true, null],' in text
    assert '"infinite": [Infinity, -Infinity]' in text
    assert '"rows": [\n      [1, 2],\n      [3]\n    ]' in text
    assert '"names": [\n    "a",\n    "b"\n  ]' in text  # strings keep a line each: their text could hold anything
    assert json.loads(text) == data
    write_json(tmp_path / "out" / "data.json", data)
    assert (tmp_path / "out" / "data.json").read_text() == text + "\n"
    assert not list((tmp_path / "out").glob("*.partial"))
