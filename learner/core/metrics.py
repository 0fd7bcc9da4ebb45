"""Training metrics to a JSON-lines file (for scripts) and TensorBoard (for people), both in the run directory.

Both are appended to, so a resumed run continues the same curves.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

from torch.utils.tensorboard import SummaryWriter

METRICS_FILE = "metrics.jsonl"
TENSORBOARD_DIR = "tensorboard"


class MetricsLog:
    def __init__(self, run_dir: Path) -> None:
        run_dir = Path(run_dir)
        run_dir.mkdir(parents=True, exist_ok=True)
        self.path = run_dir / METRICS_FILE
        self._file = self.path.open("a", encoding="utf-8")
        self._tensorboard = SummaryWriter(str(run_dir / TENSORBOARD_DIR))

    def write(self, step: int, values: dict[str, float]) -> None:
        """One record per call. NaN (say, no episode finished this iteration) becomes null in JSON
        and is left out of TensorBoard."""
        record: dict[str, float | None] = {"step": step, "time": time.time()}
        record.update({name: (None if math.isnan(value) else value) for name, value in values.items()})
        self._file.write(json.dumps(record) + "\n")
        self._file.flush()
        for name, value in values.items():
            if not math.isnan(value):
                self._tensorboard.add_scalar(name, value, step)
        self._tensorboard.flush()

    def close(self) -> None:
        self._file.close()
        self._tensorboard.close()
