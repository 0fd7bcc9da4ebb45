# syntax=docker/dockerfile:1
# One image for every role of the stack: teacher service, Ray head, Ray workers, learner.
# CPU torch by default. For a CUDA image, point TORCH_INDEX_URL at the matching PyTorch wheel index:
#   docker build --build-arg TORCH_INDEX_URL=https://download.pytorch.org/whl/cu126 -t kuka-curriculum .
FROM python:3.11-slim

ARG TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_ROOT_USER_ACTION=ignore

WORKDIR /app

# torch comes first, from its own index: the project install below then finds it satisfied
# instead of pulling PyPI's multi-GB CUDA build into the CPU image.
COPY constraints.txt ./
RUN --mount=type=cache,target=/root/.cache/pip \
    pip install --index-url "$TORCH_INDEX_URL" --constraint constraints.txt torch

COPY pyproject.toml README.md ./
COPY common ./common
COPY teacher_service ./teacher_service
COPY rollout_worker ./rollout_worker
COPY learner ./learner
# ray[default] adds the dashboard that the head publishes.
RUN --mount=type=cache,target=/root/.cache/pip \
    pip install --constraint constraints.txt . "ray[default]"

# Run unprivileged. /data (teacher database) and /runs (checkpoints, TensorBoard) exist here
# already owned by that user, so fresh named volumes mounted on them start out writable.
RUN useradd --create-home --uid 1000 kuka \
    && mkdir /data /runs \
    && chown kuka:kuka /data /runs
USER kuka

# 8000 teacher API, 6379 Ray GCS, 8265 Ray dashboard, 6006 TensorBoard.
EXPOSE 8000 6379 8265 6006

ENTRYPOINT ["kuka-curriculum"]
CMD ["--help"]
