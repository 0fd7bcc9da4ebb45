"""Bounds of the policy's action noise, in a module without torch so configs can check against them."""

from __future__ import annotations

LOG_STD_BOUNDS = (-5.0, 1.0)
"""Where a state-dependent log-std is clamped: std 0.007 to 2.7 on actions in [-1, 1], so no state's
log-density can blow up or its noise drown the action range."""
