"""The Docker deployment's files, checked in seconds without a Docker engine.

Nothing is built or started here (``test_docker_stack.py`` builds the image and runs the stack);
a mistake in a file is named here precisely instead. What is checked: Debian's ``docker-compose
config`` accepts ``docker-compose.yml`` with no ``.env`` and with ``.env.example`` filled in; the
token holders start behind the script that gives them the stack's own token or the one in ``.env``,
and nothing else; every service's command is a real invocation of the program it runs (our own
argparse sub-commands, Ray's click commands, TensorBoard's flags); ports, volumes and environment
agree with each other and with the teacher's ``Settings``; and the ``Dockerfile`` copies what
exists and starts the console script.
"""

from __future__ import annotations

import argparse
import fnmatch
import importlib
import json
import os
import re
import shlex
import shutil
import subprocess
import tomllib
import warnings
from pathlib import Path, PurePosixPath
from typing import Any
from urllib.parse import urlsplit

import click
import pytest
import yaml

from kuka_curriculum import COMMANDS
from learner.core.config import TrainConfig
from learner.job.session import PUBLIC_URL_VARIABLE
from learner.job.session import TOKEN_VARIABLE as LEARNER_TOKEN_VARIABLE
from teacher_service.core.config import Settings

ROOT = Path(__file__).resolve().parents[1]
SERVICES = {"teacher", "ray-head", "ray-worker", "learner", "tensorboard"}
TOKEN_HOLDERS = {"teacher", "learner"}
"""The teacher checks the token; the learner writes with it and hands it to its rollout actors."""
FILLED_IN_TOKEN = "deployment-test-token-0123456789"
"""What a user puts in ``.env`` where ``.env.example`` leaves the token empty."""
TOKEN_SCRIPT = ROOT / "docker" / "with-teacher-token.sh"
TOKEN_WRAPPER = "/usr/local/bin/with-teacher-token"
"""Where the Dockerfile installs ``TOKEN_SCRIPT``."""
TOKEN_VOLUME_FILE = "/secrets/teacher-token"


# --- reading the files --------------------------------------------------------------------------


def read_env_file(path: Path) -> dict[str, str]:
    entries = (line.strip() for line in path.read_text().splitlines())
    return dict(entry.split("=", 1) for entry in entries if entry and not entry.startswith("#"))


def compose_config(env_file: Path) -> subprocess.CompletedProcess[str]:
    """``docker-compose config`` with only ``env_file`` as input: the caller's environment could override it."""
    executable = shutil.which("docker-compose")
    if executable is None:
        message = "docker-compose is not installed (Debian package docker-compose; .ci/run installs it)"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    return subprocess.run(
        [executable, "--project-directory", str(ROOT), "--env-file", str(env_file), "config"],
        cwd=ROOT,
        env={"PATH": os.environ["PATH"], "HOME": os.environ.get("HOME", "/tmp")},
        capture_output=True,
        text=True,
        timeout=60,
    )


def load_compose(env_file: Path) -> dict[str, Any]:
    result = compose_config(env_file)
    assert result.returncode == 0, f"docker-compose config rejects docker-compose.yml:\n{result.stderr}"
    return yaml.safe_load(result.stdout)


def dockerfile_instructions() -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) pairs, with continuation lines joined and comments dropped."""
    instructions: list[tuple[str, str]] = []
    pending = ""
    for line in (ROOT / "Dockerfile").read_text().splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        pending += stripped.removesuffix("\\").strip() + " "
        if not stripped.endswith("\\"):
            keyword, _, arguments = pending.strip().partition(" ")
            instructions.append((keyword.upper(), arguments.strip()))
            pending = ""
    return instructions


def dockerfile_values(keyword: str) -> list[str]:
    return [arguments for instruction, arguments in dockerfile_instructions() if instruction == keyword]


def dockerfile_argument_defaults() -> dict[str, str]:
    """``ARG NAME=default`` lines; an ``ARG NAME`` without one is left unset unless the build sets it."""
    return dict(argument.split("=", 1) for argument in dockerfile_values("ARG") if "=" in argument)


def service_commands(service: dict[str, Any]) -> list[list[str]]:
    """The argument vectors a container runs: entrypoint plus command, falling back on the image's."""
    entrypoint = service.get("entrypoint") or json.loads(dockerfile_values("ENTRYPOINT")[-1])
    command = service.get("command") or json.loads(dockerfile_values("CMD")[-1])
    argv = [*entrypoint, *command]
    if argv[0] == TOKEN_WRAPPER:  # it sets the token, then runs the rest
        argv = argv[2:] if argv[1] == "--announce" else argv[1:]
    if argv[:2] != ["/bin/sh", "-c"]:
        return [argv]
    commands = [shlex.split(part) for part in argv[2].split("&&")]
    return [words[1:] if words[0] == "exec" else words for words in commands]


def command_of(service: dict[str, Any], program: str, subcommand: str) -> list[str]:
    """The one invocation of ``program subcommand`` among the service's commands."""
    matches = [argv for argv in service_commands(service) if argv[:2] == [program, subcommand]]
    assert len(matches) == 1, f"expected one `{program} {subcommand}` in {service_commands(service)}"
    return matches[0]


# --- parsing commands with the real command-line interfaces -------------------------------------


def parse_kuka_curriculum(argv: list[str]) -> argparse.Namespace:
    name, *arguments = argv[1:]
    assert name in COMMANDS, f"kuka-curriculum has no sub-command {name!r} (has: {', '.join(COMMANDS)})"
    parser = argparse.ArgumentParser(prog=f"kuka-curriculum {name}")
    COMMANDS[name].load().add_arguments(parser)
    try:
        return parser.parse_args(arguments)
    except SystemExit:
        pytest.fail(f"kuka-curriculum rejects `{shlex.join(argv)}` (its message is in the captured stderr)")


def parse_ray(argv: list[str]) -> dict[str, Any]:
    with warnings.catch_warnings():
        warnings.simplefilter(
            "ignore", DeprecationWarning
        )  # Ray's CLI module imports Ray Serve's pydantic v1-style models
        from ray.scripts.scripts import cli

    name, *arguments = argv[1:]
    assert name in cli.commands, f"ray has no command {name!r}"
    try:
        return cli.commands[name].make_context(f"ray {name}", arguments).params
    except click.ClickException as error:
        pytest.fail(f"ray rejects `{shlex.join(argv)}`: {error.format_message()}")


def parse_tensorboard(argv: list[str]) -> argparse.Namespace:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # TensorBoard's vendored html5lib warns as plugins load
        from tensorboard import program

        board = program.TensorBoard()
        try:
            board.configure(argv=argv)
        except SystemExit:
            pytest.fail(f"tensorboard rejects `{shlex.join(argv)}` (its message is in the captured stderr)")
    return board.flags


PARSERS = {"kuka-curriculum": parse_kuka_curriculum, "ray": parse_ray, "tensorboard": parse_tensorboard}


# --- fixtures ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def env_example() -> dict[str, str]:
    """``.env.example`` as a user fills it in: with a token of their own."""
    example = read_env_file(ROOT / ".env.example")
    assert example[LEARNER_TOKEN_VARIABLE] == "", ".env.example must not hold a token anyone could use as it is"
    return {**example, LEARNER_TOKEN_VARIABLE: FILLED_IN_TOKEN}


@pytest.fixture(scope="module")
def compose(tmp_path_factory: pytest.TempPathFactory, env_example: dict[str, str]) -> dict[str, Any]:
    env_file = tmp_path_factory.mktemp("compose") / "filled-in.env"
    env_file.write_text("".join(f"{name}={value}\n" for name, value in env_example.items()))
    return load_compose(env_file)


@pytest.fixture(scope="module")
def services(compose: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return compose["services"]


@pytest.fixture(scope="module")
def compose_volumes(compose: dict[str, Any]) -> set[str]:
    return set(compose["volumes"])


def ports_of(service: dict[str, Any]) -> list[tuple[str, int, int]]:
    """(host interface, host port, container port) for each published port."""
    published = []
    for entry in service.get("ports", []):
        if isinstance(entry, dict):
            published.append((entry.get("host_ip", ""), int(entry["published"]), int(entry["target"])))
        else:
            *host_ip, host_port, container_port = entry.split("/")[0].rsplit(":", 2)
            published.append(("".join(host_ip), int(host_port), int(container_port)))
    return published


def mounts_of(service: dict[str, Any]) -> dict[PurePosixPath, tuple[str, bool]]:
    """Container path -> (volume name, read-only) for each mount."""
    mounts = {}
    for entry in service.get("volumes", []):
        if isinstance(entry, dict):
            mounts[PurePosixPath(entry["target"])] = (entry["source"], bool(entry.get("read_only")))
        else:
            source, target, *mode = entry.split(":")
            mounts[PurePosixPath(target)] = (source, mode == ["ro"])
    return mounts


def environment_of(service: dict[str, Any]) -> dict[str, str]:
    environment = service.get("environment", {})
    if isinstance(environment, list):
        return dict(entry.split("=", 1) for entry in environment)
    return {name: str(value) for name, value in environment.items()}


def volume_holding(service: dict[str, Any], path: str) -> tuple[str, bool]:
    for target, mount in mounts_of(service).items():
        if PurePosixPath(path).is_relative_to(target):
            return mount
    pytest.fail(f"{path} is on no volume of the service (mounts: {service.get('volumes', [])})")


# --- docker-compose.yml ---------------------------------------------------------------------------


def test_compose_file_is_valid_and_has_every_role(services: dict[str, dict[str, Any]]) -> None:
    assert set(services) == SERVICES


@pytest.mark.parametrize("env_file", ["no .env", ".env.example"])
def test_compose_starts_without_a_token_and_its_holders_take_the_stacks_own(tmp_path: Path, env_file: str) -> None:
    """With no token in ``.env``, the config renders, and the teacher and the learner start behind the
    script that makes or reads the stack's token on the volume they share."""
    empty = tmp_path / "empty.env"
    empty.write_text("")
    services = load_compose(empty if env_file == "no .env" else ROOT / env_file)["services"]
    wrapped = {name for name, service in services.items() if (service.get("entrypoint") or [""])[0] == TOKEN_WRAPPER}
    assert wrapped == TOKEN_HOLDERS
    assert f"{TOKEN_SCRIPT.relative_to(ROOT)} {TOKEN_WRAPPER}" in dockerfile_values("COPY")
    for name in TOKEN_HOLDERS:
        assert environment_of(services[name])[LEARNER_TOKEN_VARIABLE] == ""
        volume, read_only = volume_holding(services[name], TOKEN_VOLUME_FILE)
        assert volume == "secrets" and not read_only
    assert services["learner"]["entrypoint"][1] == "--announce", "the learner's log should say how to read it"
    assert all(TOKEN_VOLUME_FILE not in str(services[name].get("volumes")) for name in SERVICES - TOKEN_HOLDERS)


def run_token_script(token_file: Path, *arguments: str, token: str = "") -> subprocess.CompletedProcess[str]:
    """The script as a container runs it, its token file moved from /secrets to ``token_file``."""
    environment = {"PATH": os.environ["PATH"], "KC_TEACHER_TOKEN_FILE": str(token_file)}
    if token:
        environment[LEARNER_TOKEN_VARIABLE] = token
    command = ["sh", str(TOKEN_SCRIPT), *arguments, "sh", "-c", f'echo "token=${LEARNER_TOKEN_VARIABLE}"']
    return subprocess.run(command, env=environment, capture_output=True, text=True, timeout=60, check=False)


def test_the_first_start_makes_a_private_random_token_that_later_starts_share(tmp_path: Path) -> None:
    token_file = tmp_path / "teacher-token"
    first = run_token_script(token_file)
    assert first.returncode == 0, first.stderr
    token = first.stdout.strip().removeprefix("token=")
    assert len(token) >= 40 and token_file.read_text().strip() == token
    assert token_file.stat().st_mode & 0o777 == 0o600
    again = run_token_script(token_file, "--announce")
    assert again.returncode == 0, again.stderr
    assert again.stdout.splitlines() == [
        f"teacher token: made on the stack's first start; read it with: docker compose exec teacher cat {token_file}",
        f"token={token}",
    ]
    other_stack = run_token_script(tmp_path / "other-token")
    assert other_stack.stdout.strip() != first.stdout.strip(), "every stack must get a token of its own"


def test_services_starting_together_agree_on_one_token(tmp_path: Path) -> None:
    token_file = tmp_path / "teacher-token"
    environment = {"PATH": os.environ["PATH"], "KC_TEACHER_TOKEN_FILE": str(token_file)}
    command = ["sh", str(TOKEN_SCRIPT), "sh", "-c", f'echo "${LEARNER_TOKEN_VARIABLE}"']
    starts = [subprocess.Popen(command, env=environment, stdout=subprocess.PIPE, text=True) for _ in range(8)]
    tokens = {start.communicate(timeout=60)[0].strip() for start in starts}
    assert tokens == {token_file.read_text().strip()}
    assert [path.name for path in tmp_path.iterdir()] == ["teacher-token"], "a draft was left behind"


def test_a_token_set_in_env_wins_and_no_token_file_is_made(tmp_path: Path) -> None:
    token_file = tmp_path / "teacher-token"
    result = run_token_script(token_file, "--announce", token=FILLED_IN_TOKEN)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == [
        "teacher token: it is KC_TEACHER_TOKEN in your .env",
        f"token={FILLED_IN_TOKEN}",
    ]
    assert not token_file.exists()


def test_without_a_token_the_service_does_not_start(tmp_path: Path) -> None:
    """A token file that cannot be written (a volume mounted read-only, say) stops the service."""
    unwritable = tmp_path / "missing-directory" / "teacher-token"
    result = run_token_script(unwritable)
    assert result.returncode != 0 and "token=" not in result.stdout


def test_teacher_answers_the_host_names_the_stack_uses(services: dict[str, dict[str, Any]]) -> None:
    teacher = services["teacher"]
    environment = environment_of(teacher)
    settings = Settings(
        teacher_token=environment[LEARNER_TOKEN_VARIABLE], allowed_hosts=environment.get("KC_ALLOWED_HOSTS")
    )
    names = set(settings.host_names())
    train = parse_kuka_curriculum(command_of(services["learner"], "kuka-curriculum", "train"))
    probe = " ".join(teacher["healthcheck"]["test"])
    used = {
        urlsplit(train.teacher_url).hostname,
        urlsplit(re.search(r"http://[^'\" ]+", probe).group()).hostname,
        urlsplit(environment_of(services["learner"])[PUBLIC_URL_VARIABLE]).hostname,
    }
    assert "*" in names or used <= names, f"the teacher answers {sorted(names)}, the stack reaches it as {sorted(used)}"


@pytest.mark.parametrize("name", sorted(SERVICES))
def test_every_command_is_accepted_by_the_program_it_runs(services: dict[str, dict[str, Any]], name: str) -> None:
    service = services[name]
    healthcheck = service.get("healthcheck", {}).get("test", [])
    commands = service_commands(service)
    if healthcheck[:2] == ["CMD", "ray"]:
        commands.append(healthcheck[1:])
    for argv in commands:
        assert argv[0] in PARSERS, f"{name} runs {argv[0]!r}, which is neither kuka-curriculum, ray nor tensorboard"
        PARSERS[argv[0]](argv)


def test_published_ports_listen_on_loopback_only(services: dict[str, dict[str, Any]]) -> None:
    published = {name: ports_of(service) for name, service in services.items() if "ports" in service}
    assert set(published) == {"teacher", "ray-head", "tensorboard"}
    for name, ports in published.items():
        for host_ip, _, _ in ports:
            assert host_ip == "127.0.0.1", f"{name} publishes a port on {host_ip or 'every interface'}"


def test_learner_links_the_dashboard_where_the_host_reaches_the_teacher(services: dict[str, dict[str, Any]]) -> None:
    [(host_ip, host_port, _)] = ports_of(services["teacher"])
    assert environment_of(services["learner"])[PUBLIC_URL_VARIABLE] == f"http://{host_ip}:{host_port}"


def test_teacher_is_reached_where_it_listens(services: dict[str, dict[str, Any]]) -> None:
    teacher = services["teacher"]
    args = parse_kuka_curriculum(command_of(teacher, "kuka-curriculum", "serve"))
    settings = Settings(**{name: value for name, value in vars(args).items() if value is not None})
    assert settings.host == "0.0.0.0", "a service bound to the container's loopback is unreachable from the others"
    assert [target for _, _, target in ports_of(teacher)] == [settings.port]

    probe = " ".join(teacher["healthcheck"]["test"])
    health_url = urlsplit(re.search(r"http://[^'\" ]+", probe).group())
    assert (health_url.port, health_url.path) == (settings.port, "/healthz")

    train = parse_kuka_curriculum(command_of(services["learner"], "kuka-curriculum", "train"))
    assert urlsplit(train.teacher_url)[:2] == ("http", f"teacher:{settings.port}")


def test_teacher_database_lives_on_a_named_volume(
    services: dict[str, dict[str, Any]], compose_volumes: set[str]
) -> None:
    teacher = services["teacher"]
    args = parse_kuka_curriculum(command_of(teacher, "kuka-curriculum", "serve"))
    database = Settings(**({"db": args.db} if args.db else {})).db
    assert database.is_absolute(), "a relative database path would land in the image's working directory"
    volume, read_only = volume_holding(teacher, str(database))
    assert volume in compose_volumes and not read_only


def test_ray_nodes_join_the_head_by_service_name(services: dict[str, dict[str, Any]]) -> None:
    head = parse_ray(command_of(services["ray-head"], "ray", "start"))
    assert head["head"] and head["block"]
    head_address = f"ray-head:{head['port']}"

    worker = parse_ray(command_of(services["ray-worker"], "ray", "start"))
    assert worker["address"] == head_address and worker["block"]
    learner_node = parse_ray(command_of(services["learner"], "ray", "start"))
    assert learner_node["address"] == head_address
    assert learner_node["num_cpus"] == 0, "rollout actors belong on the workers, not beside the learner"
    train = parse_kuka_curriculum(command_of(services["learner"], "kuka-curriculum", "train"))
    assert train.ray_address == head_address

    health = parse_ray(services["ray-head"]["healthcheck"]["test"][1:])
    assert health["address"].endswith(f":{head['port']}")


def test_ray_dashboard_is_published(services: dict[str, dict[str, Any]]) -> None:
    head = parse_ray(command_of(services["ray-head"], "ray", "start"))
    assert head["include_dashboard"] is True, "left to Ray, a missing dashboard dependency would go unnoticed"
    assert head["dashboard_host"] == "0.0.0.0"
    assert [target for _, _, target in ports_of(services["ray-head"])] == [head["dashboard_port"]]


def test_ray_workers_can_be_scaled(services: dict[str, dict[str, Any]]) -> None:
    worker = services["ray-worker"]
    assert "container_name" not in worker, "a fixed container name allows one replica only"
    assert "ports" not in worker, "a published host port allows one replica only"


def test_learner_waits_for_a_healthy_teacher_and_head(services: dict[str, dict[str, Any]]) -> None:
    depends_on = services["learner"]["depends_on"]
    for dependency in ("teacher", "ray-head"):
        assert depends_on[dependency]["condition"] == "service_healthy"
        assert services[dependency]["healthcheck"]["test"]


def test_a_restarted_learner_carries_on_and_a_finished_one_stays_down(services: dict[str, dict[str, Any]]) -> None:
    learner = services["learner"]
    assert parse_kuka_curriculum(command_of(learner, "kuka-curriculum", "train")).resume_if_exists
    assert learner["restart"] == "on-failure", "a finished run exits 0; restarting it would loop"


def test_tensorboard_reads_the_learner_run_directory(
    services: dict[str, dict[str, Any]], compose_volumes: set[str]
) -> None:
    learner = services["learner"]
    train = parse_kuka_curriculum(command_of(learner, "kuka-curriculum", "train"))
    run_volume, read_only = volume_holding(learner, str(train.run_dir))
    assert run_volume in compose_volumes and not read_only

    board = services["tensorboard"]
    flags = parse_tensorboard(service_commands(board)[0])
    assert flags.host == "0.0.0.0"
    assert [target for _, _, target in ports_of(board)] == [flags.port]
    assert volume_holding(board, flags.logdir) == (run_volume, True)


def test_environment_names_are_read_by_the_programs(
    services: dict[str, dict[str, Any]], env_example: dict[str, str]
) -> None:
    prefix = Settings.model_config["env_prefix"]
    known = {prefix + field.upper() for field in Settings.model_fields} | {PUBLIC_URL_VARIABLE}
    assert LEARNER_TOKEN_VARIABLE in known, (
        "the learner must send the token from the variable the teacher reads it from"
    )
    for name, service in services.items():
        for variable in environment_of(service):
            if variable.startswith(prefix):
                assert variable in known, f"{name} sets {variable}, which neither the teacher nor the learner reads"

    holders = {name for name, service in services.items() if LEARNER_TOKEN_VARIABLE in environment_of(service)}
    assert holders == TOKEN_HOLDERS
    tokens = {environment_of(services[name])[LEARNER_TOKEN_VARIABLE] for name in holders}
    assert tokens == {env_example[LEARNER_TOKEN_VARIABLE]}


def test_env_file_drives_the_training_run(
    tmp_path: Path, env_example: dict[str, str], services: dict[str, dict[str, Any]]
) -> None:
    chosen = {
        "TEACHER": "manual",
        "KUKA_ENV": "KukaGraspHard-v1",
        "TOTAL_STEPS": "12345",
        "ROLLOUT_WORKERS": "6",
        "ENVS_PER_WORKER": "3",
        "SEED": "7",
    }
    assert set(chosen) <= set(env_example), ".env.example should list every setting a user is expected to change"
    env_file = tmp_path / "custom.env"
    env_file.write_text("".join(f"{name}={value}\n" for name, value in {**env_example, **chosen}.items()))

    train = parse_kuka_curriculum(command_of(load_compose(env_file)["services"]["learner"], "kuka-curriculum", "train"))
    assert (train.teacher, train.env, train.total_steps, train.workers, train.envs_per_worker, train.seed) == (
        "manual",
        "KukaGraspHard-v1",
        12345,
        6,
        3,
        7,
    )

    defaults = parse_kuka_curriculum(command_of(services["learner"], "kuka-curriculum", "train"))
    assert defaults.teacher == env_example["TEACHER"]
    assert defaults.env == env_example["KUKA_ENV"] == TrainConfig().env


# --- Dockerfile ------------------------------------------------------------------------------------


def test_dockerfile_copies_every_package_and_nothing_missing_or_ignored() -> None:
    ignored = [
        line.strip()
        for line in (ROOT / ".dockerignore").read_text().splitlines()
        if line.strip() and not line.startswith("#")
    ]
    sources = [source for arguments in dockerfile_values("COPY") for source in arguments.split()[:-1]]
    for source in sources:
        assert (ROOT / source).exists(), f"COPY {source}: no such file in the build context"
        assert not any(fnmatch.fnmatch(source, pattern) for pattern in ignored), (
            f"COPY {source}, but .dockerignore drops it"
        )

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    packages = {pattern.rstrip("*") for pattern in project["tool"]["setuptools"]["packages"]["find"]["include"]}
    assert packages <= set(sources), f"the image misses packages: {sorted(packages - set(sources))}"
    assert project["project"]["readme"] in sources, "pip install needs the readme pyproject.toml names"


def test_image_starts_the_console_script(capsys: pytest.CaptureFixture[str]) -> None:
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    [program] = json.loads(dockerfile_values("ENTRYPOINT")[-1])
    assert program in scripts, f"ENTRYPOINT {program!r} is not a console script of pyproject.toml"

    module_path, _, function = scripts[program].partition(":")
    with pytest.raises(SystemExit) as exit_info:
        getattr(importlib.import_module(module_path), function)(json.loads(dockerfile_values("CMD")[-1]))
    assert exit_info.value.code == 0
    usage = capsys.readouterr().out
    assert all(name in usage for name in COMMANDS), "a bare `docker run` should list the sub-commands"


def test_torch_comes_from_the_index_the_build_argument_names() -> None:
    default_index = dockerfile_argument_defaults()["TORCH_INDEX_URL"]
    assert default_index.endswith("/whl/cpu")
    torch_install = next(run for run in dockerfile_values("RUN") if "/^torch==/" in run)
    assert '--index-url "$TORCH_INDEX_URL"' in torch_install and "--require-hashes" in torch_install


def test_the_image_installs_every_dependency_from_the_lock_with_hashes() -> None:
    """Each ``pip install`` takes its versions from requirements.txt (``make lock``), hashes checked; the
    project itself comes last, without dependencies, so nothing is resolved afresh in the image."""
    installs = [run for run in dockerfile_values("RUN") if "pip install" in run]
    project_install = installs.pop()
    assert "--no-deps" in project_install and project_install.split("&&")[0].rstrip().endswith(" .")
    assert installs and all("--require-hashes --requirement" in run for run in installs)
    assert any("--requirement requirements.txt" in run for run in installs)


def test_build_arguments_in_env_example_match_the_dockerfile(
    services: dict[str, dict[str, Any]], env_example: dict[str, str]
) -> None:
    dockerfile_defaults = dockerfile_argument_defaults()
    for name, service in services.items():
        for argument, value in service["build"]["args"].items():
            assert value == env_example[argument], f"{name}: build argument {argument} is not set from .env"
            assert value == dockerfile_defaults.get(argument, value), f"{argument}: .env.example and Dockerfile differ"
    assert {"BASE_IMAGE", "TORCH_INDEX_URL"} <= set(dockerfile_defaults)


def test_image_exposes_every_published_container_port(services: dict[str, dict[str, Any]]) -> None:
    exposed = {int(port) for arguments in dockerfile_values("EXPOSE") for port in arguments.split()}
    published = {target for service in services.values() for _, _, target in ports_of(service)}
    assert published <= exposed
