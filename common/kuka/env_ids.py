"""The KUKA environments' gymnasium IDs, apart from the package that registers them, so the
environment and its task spaces can name them without importing the package that imports them."""

ENV_ID = "KukaGrasp-v0"
HARD_ENV_ID = "KukaGraspHard-v0"
HARD_V1_ENV_ID = "KukaGraspHard-v1"
ENV_IDS = (ENV_ID, HARD_ENV_ID, HARD_V1_ENV_ID)
