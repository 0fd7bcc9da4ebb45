"""The HTTP routes, one module per resource: curricula, teacher kinds, and health with metrics."""
