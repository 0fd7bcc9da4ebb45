"""A rollout worker's process must not load torch: the import is most of a worker's start-up time,
and the worker runs the policy in numpy. A fresh interpreter imports what Ray loads in a worker."""

import subprocess
import sys


def test_the_rollout_actor_and_its_policy_load_without_torch():
    probe = (
        "import sys\n"
        "import rollout_worker.actor, rollout_worker.sampler, common.policy.inference\n"
        "print(sorted(name for name in sys.modules if name == 'torch' or name.startswith('torch.')))\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"
