# One image for every role of the stack: teacher service, Ray head, Ray workers, learner, TensorBoard.
#
# It builds with the classic builder (Debian's docker-compose 1.29, DOCKER_BUILDKIT=0) and with BuildKit
# alike: no `# syntax=` line (BuildKit would fetch that frontend from Docker Hub) and no `RUN --mount`.
#
# Where everything comes from is a build argument, so the image also builds air-gapped (docs/deployment.md):
#   BASE_IMAGE       any image with Python 3.11 (the lock's torch is a cp311 wheel) and its venv module as
#                    `python3` (default: the slim Python image)
#   TORCH_INDEX_URL  the PyTorch wheel index: CPU, as the lock pins torch's CPU build; a CUDA image needs
#                    that build in constraints.txt (e.g. torch==2.13.0+cu126), `make lock`, and its index
#   PIP_INDEX_URL    the index for every other wheel (default PyPI)
#   PIP_FIND_LINKS   a wheelhouse URL (a directory listing); with PIP_NO_INDEX=1 it is the only source
ARG BASE_IMAGE=python:3.11-slim
FROM ${BASE_IMAGE}

ARG TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu
ARG PIP_INDEX_URL
ARG PIP_FIND_LINKS
ARG PIP_NO_INDEX

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_ROOT_USER_ACTION=ignore \
    VIRTUAL_ENV=/opt/venv \
    PATH=/opt/venv/bin:$PATH

# A virtual environment works the same on any base, including a Debian one whose system Python
# refuses pip installs (PEP 668).
RUN python3 -m venv /opt/venv

WORKDIR /app

# Dependencies before the code, each in its own layer, so that a change to the code rebuilds in seconds.
# Every version comes from requirements.txt, the runtime lock (`make lock`), and pip checks each wheel
# against the lock's hashes, so the image holds the releases the dev venv is tested with.
# torch first, from its own index: the lock pins its CPU build (2.13.0+cpu), which only that index (or
# a wheelhouse) has. Its C++ headers and its own test suite (150 MB) serve only extension builds and
# torch's developers.
COPY requirements.txt ./
RUN awk '/^torch==/ { keep = 1; print; next } keep && /^ +--hash/ { print; next } { keep = 0 }' requirements.txt \
        > /tmp/torch.txt \
    && pip install --index-url "$TORCH_INDEX_URL" --no-deps --require-hashes --requirement /tmp/torch.txt \
    && rm /tmp/torch.txt \
    && rm -rf /opt/venv/lib/python3*/site-packages/torch/include /opt/venv/lib/python3*/site-packages/torch/test

# The rest of the lock: the core dependencies, ray[default] (the dashboard the head publishes: the stack
# extra) and setuptools, the project's build backend (so the project's own install needs no index), with
# no dev tools and no ffmpeg. The packages' bundled test suites go in the same layer, or they would still
# weigh on the image.
RUN pip install --require-hashes --requirement requirements.txt \
    && find /opt/venv/lib -depth -type d -name tests -path '*/site-packages/*' -exec rm -rf {} +

COPY pyproject.toml ./
COPY README.md ./
COPY kuka_curriculum.py ./
COPY common ./common
COPY teacher_service ./teacher_service
COPY rollout_worker ./rollout_worker
COPY learner ./learner
RUN pip install --no-deps --no-build-isolation . \
    && rm -rf build ./*.egg-info

# The compose stack's token holders start behind it: it sets KC_TEACHER_TOKEN, from .env or the one it
# makes on the first start in /secrets (docker-compose.yml).
COPY docker/with-teacher-token.sh /usr/local/bin/with-teacher-token

# Run unprivileged. /data (teacher database), /runs (checkpoints, TensorBoard) and /secrets (the token,
# for that user alone) exist here already owned by it, so fresh named volumes mounted on them start out
# writable.
RUN useradd --create-home --uid 1000 kuka \
    && mkdir /data /runs /secrets \
    && chown kuka:kuka /data /runs /secrets \
    && chmod 0700 /secrets \
    && chmod 0755 /usr/local/bin/with-teacher-token
USER kuka

# 8000 teacher API, 6379 Ray GCS, 8265 Ray dashboard, 6006 TensorBoard.
EXPOSE 8000 6379 8265 6006

ENTRYPOINT ["kuka-curriculum"]
CMD ["--help"]
