"""Take a curriculum's tasks from a teacher service: its API schemas, task space, HTTP client and
gymnasium wrapper.

This package needs only numpy, pydantic, httpx and gymnasium (the ``client`` extra), never torch, Ray
or PyBullet, so a trainer of another library can use it alone.
"""
