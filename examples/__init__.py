"""Runnable examples of training through the teacher service; a package so tests can import their parts."""
