"""A training job's surroundings, shared by ``train``, ``tune`` and ``bakeoff``: the write token, the teacher
service (reached, or started for the run) and its status line, and Ray (joined, or started locally)."""
