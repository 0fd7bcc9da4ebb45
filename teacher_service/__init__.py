"""The teacher service: owns the curricula, hands out tasks and learns from episode results."""
