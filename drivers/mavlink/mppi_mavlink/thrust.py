"""Collective thrust: mppid plans in newtons, autopilots take a normalised 0..1 thrust.

The map is anchored at hover: the autopilot's hover-thrust fraction h (PX4 MPC_THR_HOVER,
ArduPilot MOT_THST_HOVER) produces the weight m g, and thrust is taken as linear in the
normalised command (the model PX4's hover-thrust estimator and ArduPilot's thrust
linearisation both assume around hover):

    thrust_norm = clamp(h * T / (m g), 0, 1),    T = thrust_norm * m g / h.

So the largest thrust the bridge can ask for is m g / h: with h = 0.4 and 1 kg, 24.5 N.
"""
from __future__ import annotations

import math


class ThrustMap:
    def __init__(self, mass: float, gravity: float, hover_fraction: float):
        for name, v in (("mass", mass), ("gravity", gravity), ("hover_fraction", hover_fraction)):
            if not math.isfinite(v) or v <= 0.0:
                raise ValueError(f"thrust map: {name} must be finite and > 0, got {v}")
        if hover_fraction >= 1.0:
            raise ValueError(f"thrust map: hover_fraction must be < 1, got {hover_fraction}")
        self.mass, self.gravity, self.hover = float(mass), float(gravity), float(hover_fraction)
        self.weight = self.mass * self.gravity

    def to_normalized(self, thrust_n: float) -> float:
        """Newtons -> 0..1 (clamped). Raises ValueError for a non-finite input."""
        if not math.isfinite(thrust_n):
            raise ValueError("non-finite thrust")
        return min(1.0, max(0.0, self.hover * thrust_n / self.weight))

    def to_newtons(self, thrust_norm: float) -> float:
        return thrust_norm * self.weight / self.hover

    @property
    def max_thrust(self) -> float:
        return self.weight / self.hover
