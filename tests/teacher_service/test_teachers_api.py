"""``GET /api/v1/teachers`` against a real service: every registered kind, its parameters as its
model declares them, and bounds that are the ones a curriculum request is held to."""

from __future__ import annotations

from typing import Any

import httpx
import pytest

from teacher_service.teachers import TEACHER_KINDS


@pytest.fixture(scope="module")
def catalogue(http: httpx.Client) -> dict[str, dict[str, Any]]:
    response = http.get("/teachers")
    assert response.status_code == 200, response.text
    return {entry["kind"]: entry for entry in response.json()["teachers"]}


def test_every_registered_kind_is_listed_with_its_parameters_and_defaults(catalogue):
    assert sorted(catalogue) == sorted(TEACHER_KINDS)
    for kind, teacher in TEACHER_KINDS.items():
        entry = catalogue[kind]
        assert entry["summary"] and "\n" not in entry["summary"]
        assert entry["summary"].split()[:3] == (teacher.__doc__ or "").split()[:3]
        defaults = teacher.Params().model_dump(mode="json")
        assert {p["name"]: p["default"] for p in entry["parameters"]} == defaults
        for parameter in entry["parameters"]:
            field = teacher.Params.model_fields[parameter["name"]]
            assert parameter["doc"] == " ".join((field.description or "").split()) != ""


def test_the_manual_plans_parameters_carry_their_bounds_types_and_choices(catalogue):
    parameters = {p["name"]: p for p in catalogue["manual"]["parameters"]}
    assert parameters["window"] | {"json_schema": None} == {
        "name": "window",
        "type": "integer",
        "default": 100,
        "doc": parameters["window"]["doc"],
        "minimum": 1,
        "maximum": 10_000,
        "exclusive_minimum": None,
        "exclusive_maximum": None,
        "max_items": None,
        "choices": None,
        "json_schema": None,
    }
    assert parameters["steps"]["type"] == "integer | null"
    assert (parameters["steps"]["minimum"], parameters["steps"]["maximum"]) == (2, 1000)
    assert parameters["lessons"]["type"] == "array | null" and parameters["lessons"]["max_items"] == 1000
    assert parameters["metric"]["choices"] == ["reward", "success"]


def test_each_listed_bound_is_enforced_and_the_listed_defaults_are_accepted(catalogue, http, kuka_space):
    for kind, entry in catalogue.items():
        defaults = {p["name"]: p["default"] for p in entry["parameters"]}
        space = (
            kuka_space
            if "float" in entry["parameter_types"]
            else [{"name": "level", "type": "integer", "low": 0, "high": 9}]
        )
        body = {"teacher": kind, "space": space, "params": defaults, "seed": 0}
        assert http.put(f"/curricula/listed-{kind}", json=body).status_code == 201
        for parameter in entry["parameters"]:
            step = 1 if parameter["type"].startswith("integer") else 0.5
            for beyond in (
                None if parameter["maximum"] is None else parameter["maximum"] + step,
                None if parameter["minimum"] is None else parameter["minimum"] - step,
            ):
                if beyond is None:
                    continue
                outside = {**body, "params": {parameter["name"]: beyond}}
                refused = http.put(f"/curricula/outside-{kind}", json=outside)
                assert refused.status_code == 422, (kind, parameter["name"], beyond, refused.text)
                assert parameter["name"] in str(refused.json()["detail"][0]["loc"])


def test_the_openapi_schema_types_the_answer(http, service):
    schema = httpx.get(f"{service.url}/openapi.json", timeout=10).json()
    answer = schema["paths"]["/api/v1/teachers"]["get"]["responses"]["200"]["content"]["application/json"]["schema"]
    assert answer == {"$ref": "#/components/schemas/TeacherKindList"}
    assert {"kind", "summary", "parameters"} <= set(schema["components"]["schemas"]["TeacherKindInfo"]["properties"])
