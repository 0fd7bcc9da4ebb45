"""The teachers' algorithms on their own: numpy in, numpy out, no counters, no saving (the teacher
adapters in ``teachers`` keep those)."""
