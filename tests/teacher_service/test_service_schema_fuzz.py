"""Schemathesis over the service's own OpenAPI schema: generated requests to every operation, valid
and invalid, go to a real service and must never get a 5xx; every answer must match what the
schema documents.

The schema comes from the app object (building it starts nothing), because schemathesis's lazy
fixture loader does not run under pytest 9.
"""

from __future__ import annotations

import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from teacher_service.app import create_app
from teacher_service.process import ServiceProcess

schema = schemathesis.openapi.from_dict(create_app().openapi())


@schema.parametrize()
@settings(max_examples=30, deadline=None, suppress_health_check=list(HealthCheck))
def test_no_server_errors_and_answers_match_the_schema(
    case: schemathesis.Case, service: ServiceProcess, write_token: str
) -> None:
    case.call_and_validate(
        base_url=service.url,
        headers={"Authorization": f"Bearer {write_token}"},
        checks=[not_a_server_error, status_code_conformance, content_type_conformance, response_schema_conformance],
    )
