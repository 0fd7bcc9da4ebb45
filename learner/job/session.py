"""A training job's connections, shared by ``train``, ``tune`` and ``bakeoff``: the write token from
the environment, the teacher service (reached, or started for the run), the curriculum registered
with it, and Ray (joined, or started locally). Each failure a person can fix is a ``UsageError``.
"""

from __future__ import annotations

import contextlib
import os
import re
import socket
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pydantic import SecretStr

from common.client.write_token import TOKEN_VARIABLE, token_problem
from learner.commands.arguments import UsageError
from learner.core.config import TrainConfig

RAY_CONNECT_TIMEOUT_S = 5.0
TEACHER_CONNECT_TIMEOUT_S = 10.0
RAY_NAMESPACE = "kuka-curriculum"
PUBLIC_URL_VARIABLE = "KC_PUBLIC_URL"
"""The teacher's address as a person's browser reaches it, when it differs from ``--teacher-url``
(in Docker Compose the learner reaches ``http://teacher:8000``, the host ``http://127.0.0.1:8000``)."""
RAY_WATCH_INTERVAL_S = 10.0
RAY_LOST_EXIT_CODE = 75
"""EX_TEMPFAIL: the job lost its Ray cluster; a restart (compose's ``restart: on-failure``) resumes it."""
RAY_AUTH_MODE_VARIABLE = "RAY_AUTH_MODE"
"""Unset, Ray turns token authentication on for a new local cluster and warns that it chose so; set to
Ray's own choice before Ray is imported (it reads the mode once), it keeps that and drops the warning."""


def token_from_environment() -> SecretStr | None:
    """The teacher service's bearer token, from ``KC_TEACHER_TOKEN`` (never a flag: flags show in
    ``ps``); refused before anything starts when it is a placeholder or too short to be secret."""
    token = os.environ.get(TOKEN_VARIABLE) or None
    if token is None:
        return None
    problem = token_problem(token)
    if problem is not None:
        raise UsageError(problem)
    return SecretStr(token)


def launch_teacher(url: str | None, run_dir: Path, stack: contextlib.ExitStack) -> Callable[[], str]:
    """A wait for the teacher service's URL: a service of its own in ``run_dir``, launched now so the
    caller can start Ray while it starts, or the one at ``url``, checked at once so a wrong address
    fails before Ray starts."""
    from learner.job.teacher_process import launch_local_teacher_service

    if url is None:
        ready = launch_local_teacher_service(run_dir, stack)

        def local_url() -> str:
            try:
                return ready()
            except RuntimeError as error:
                raise UsageError(str(error)) from None

        return local_url
    checked = reachable_teacher(url)
    return lambda: checked


def reachable_teacher(url: str) -> str:
    url = url.rstrip("/")
    import httpx

    try:
        httpx.get(f"{url}/healthz", timeout=TEACHER_CONNECT_TIMEOUT_S).raise_for_status()
    except httpx.HTTPError as error:
        raise UsageError(
            f"cannot reach the teacher service at {url} ({error}); start it with "
            "`kuka-curriculum serve` or leave out --teacher-url to start one"
        ) from None
    return url


def register_curriculum(url: str, name: str, config: TrainConfig, token: SecretStr | None) -> None:
    from common.client.teacher_client import TeacherClient, TeacherClientError

    with TeacherClient(url, name, token=token) as client:
        try:
            client.register(
                config.teacher,
                config.task_space(),
                params=config.teacher_params,
                seed=config.seed,
                timeout=TEACHER_CONNECT_TIMEOUT_S,
            )
        except TeacherClientError as error:
            raise UsageError(f"cannot register curriculum {name!r} at {url}: {error}") from None


def check_ray_reachable(ray_address: str) -> None:
    """Fail in seconds, not after Ray's own minute of retries, when nothing listens at the address."""
    host, _, port = ray_address.removeprefix("ray://").rpartition(":")
    try:
        socket.create_connection((host, int(port)), timeout=RAY_CONNECT_TIMEOUT_S).close()
    except (OSError, ValueError) as error:
        raise UsageError(
            f"cannot reach Ray at {ray_address!r} ({error}); expected host:port of a running "
            "cluster, or leave out --ray-address to start a local one"
        ) from None


def connect_ray(address: str | None, min_cpus: int, stack: contextlib.ExitStack) -> None:
    """Join the cluster at ``address``, or start a local one counting at least ``min_cpus`` CPUs (so the
    job's actors always fit), with Ray's token authentication chosen before Ray is first imported."""
    import logging

    if address is None and "ray" not in sys.modules:
        os.environ.setdefault(RAY_AUTH_MODE_VARIABLE, "token")
    import ray

    options: dict[str, Any] = {"log_to_driver": False, "logging_level": logging.WARNING, "namespace": RAY_NAMESPACE}
    try:
        if address is None:
            ray.init(num_cpus=max(min_cpus, os.cpu_count() or 1), include_dashboard=False, **options)
        else:
            ray.init(address=address, **options)
    except (ConnectionError, RuntimeError, ValueError) as error:
        raise UsageError(f"cannot connect to Ray at {address or 'a new local cluster'}: {error}") from None
    stack.callback(ray.shutdown)
    if address is not None:
        stack.callback(watch_ray_cluster(ray.get_runtime_context().get_node_id(), ray.nodes).set)


def watch_ray_cluster(
    node_id: str, nodes: Callable[[], list[dict[str, Any]]], interval_s: float = RAY_WATCH_INTERVAL_S
) -> threading.Event:
    """End the process with ``RAY_LOST_EXIT_CODE`` once the joined cluster stops counting this
    driver's node alive (or cannot say, twice in a row); returns the event that stops the watch.

    A Ray head killed and restarted under a training job (Docker's restart policy does this, as
    ``bench/chaos.py`` found) comes back as a new cluster that knows none of the job's actors or its
    node: the driver's waits on its rollout actors then never end, and its container stays up, so
    nothing restarts it. Exiting instead lets compose's ``restart: on-failure`` start it again and
    ``--resume-if-exists`` carry on from the last checkpoint. While the old head's address answers
    nothing, Ray itself may abort the process inside ``ray.nodes()`` (a failed check in its
    ``GetAllNodeInfo``, seen in the chaos bench) before the second check: the process still ends
    non-zero, which is what the restart needs."""
    stop = threading.Event()

    def watch() -> None:
        doubts = 0
        while not stop.wait(interval_s):
            try:
                alive = any(node.get("NodeID") == node_id and node.get("Alive") for node in nodes())
                reason = "the cluster no longer counts this node alive (was its head restarted?)"
            except Exception as error:  # the head away: Ray's calls raise
                alive, reason = False, f"{type(error).__name__}: {error}"
            doubts = 0 if alive else doubts + 1
            if doubts >= 2 and not stop.is_set():
                print(
                    f"lost the Ray cluster: {reason}; exiting with {RAY_LOST_EXIT_CODE} so that a restart "
                    "resumes from the last checkpoint",
                    file=sys.stderr,
                    flush=True,
                )
                os._exit(RAY_LOST_EXIT_CODE)

    threading.Thread(target=watch, name="ray-cluster-watch", daemon=True).start()
    return stop


def curriculum_name(run_dir: Path) -> str:
    """The run directory's name, made into a valid curriculum name: one run, one curriculum."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "-", run_dir.resolve().name).lstrip("_.-")
    return (name or "run")[:64]
