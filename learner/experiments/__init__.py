"""Experiments built on the learner: bake-offs, tunes, their reports, and the research analyses
(curriculum diagnostics, placement bands, wrist turns, task hardness, alignment at touchdown) that
the results pages read."""
