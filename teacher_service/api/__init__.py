"""The HTTP edge of the teacher service: routes, typed dependencies, error handlers, response bodies."""
