# The front door: `make train` and `make test` each build .venv when needed, then run.
VENV   := .venv
PYTHON := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: install train check lock lock-check large-files test bench clean

# Every library at the version requirements-dev.txt pins, each wheel checked against its hash; then the
# project itself, without dependencies (setuptools, its build backend, is in the lock too).
$(STAMP): pyproject.toml requirements-dev.txt
	test -x $(PYTHON) || python3 -m venv $(VENV)
	$(PYTHON) -m pip install --quiet --require-hashes --requirement requirements-dev.txt
	$(PYTHON) -m pip install --quiet --no-deps --no-build-isolation --editable .
	touch $(STAMP)

install: $(STAMP)

train: $(STAMP)
	$(VENV)/bin/kuka-curriculum train

# Refresh the locks after changing pyproject.toml or constraints.txt (it keeps every pin it can; for the
# newest releases: make lock UPGRADE=--upgrade). The dev lock is resolved first; the runtime lock (the
# Docker image's) takes its versions, so both install the same releases. `stamp` records what they were
# compiled from, for lock-check, and drops the project's own entry. Needs the network; minutes.
PIP_COMPILE := CUSTOM_COMPILE_COMMAND="make lock" $(VENV)/bin/pip-compile --quiet --generate-hashes --allow-unsafe \
	--strip-extras --all-build-deps --no-emit-index-url --no-emit-find-links $(UPGRADE) --constraint constraints.txt
lock: $(STAMP)
	$(PIP_COMPILE) --extra dev --output-file requirements-dev.txt pyproject.toml
	$(PYTHON) .ci/lock.py stamp
	$(PIP_COMPILE) --extra stack --constraint requirements-dev.txt --output-file requirements.txt pyproject.toml
	$(PYTHON) .ci/lock.py stamp

# Offline and instant: the locks were compiled from today's pyproject.toml, and pin what it asks for.
lock-check: $(STAMP)
	$(PYTHON) .ci/lock.py check

# No tracked file over 5 MB, and a bounded total outside models/ (.ci/large_files.py).
large-files:
	python3 .ci/large_files.py

# The code-health gates; configured in pyproject.toml, also run on commit by .pre-commit-config.yaml.
check: $(STAMP) lock-check large-files
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/mypy

# The tests that need no Docker on TEST_WORKERS processes (pytest-xdist; a file's tests stay together, so a
# module's service or Ray run is set up once), which overlap one test's waiting with another's computing:
# three on two cores, since each test process computes on one thread (tests/conftest.py) and waits often;
# then the Docker tests, one after another on the one stack they share (tests/docker_stack.py).
TEST_WORKERS ?= 3
test: check
	$(VENV)/bin/pytest --numprocesses $(TEST_WORKERS) --dist loadfile -m "not docker"
	$(VENV)/bin/pytest -m docker

# The teacher client alone (client/, the distribution kuka-curriculum-client): its sdist and wheel in dist/,
# to `pip install dist/kuka_curriculum_client-*.whl` where a trainer needs no torch, Ray or PyBullet.
.PHONY: client-wheel
client-wheel: $(STAMP)
	$(PYTHON) -m build --no-isolation --outdir dist client

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
