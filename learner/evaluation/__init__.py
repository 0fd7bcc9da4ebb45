"""How good a policy is: its final evaluation with error bars (``evaluate``, ``bakeoff``), the placement bands
that say where a KUKA student fails, the intervals, and the process pool the episodes share out over."""
