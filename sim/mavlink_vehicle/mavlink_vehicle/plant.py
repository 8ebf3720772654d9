"""The rate-controlled quadrotor, the equations of core/include/mppi/models/quadrotor_rate.hpp
(world ENU, body FLU, q body->world, first-order rate loop), integrated with RK4, plus what
a flight needs that the controller's model leaves out: saturation, and the ground."""
from __future__ import annotations

import math

from mppi_mavlink.layout import QuadrotorRate as Q


class Params:
    def __init__(self, mass=1.0, gravity=9.81, rate_tau=0.05, drag=0.0, max_thrust=24.525, max_body_rate=8.0):
        self.mass, self.gravity, self.rate_tau, self.drag = mass, gravity, rate_tau, drag
        self.max_thrust, self.max_body_rate = max_thrust, max_body_rate


def derivative(p: Params, x, u):
    qw, qx, qy, qz = x[Q.QW], x[Q.QX], x[Q.QY], x[Q.QZ]
    wx, wy, wz = x[Q.WX], x[Q.WY], x[Q.WZ]
    bx = 2.0 * (qx * qz + qw * qy)
    by = 2.0 * (qy * qz - qw * qx)
    bz = 1.0 - 2.0 * (qx * qx + qy * qy)
    a = u[Q.THRUST] / p.mass
    d = p.drag / p.mass
    k = 1.0 / p.rate_tau
    return [x[Q.VX], x[Q.VY], x[Q.VZ],
            a * bx - d * x[Q.VX], a * by - d * x[Q.VY], a * bz - p.gravity - d * x[Q.VZ],
            0.5 * (-qx * wx - qy * wy - qz * wz),
            0.5 * (qw * wx + qy * wz - qz * wy),
            0.5 * (qw * wy - qx * wz + qz * wx),
            0.5 * (qw * wz + qx * wy - qy * wx),
            k * (u[Q.RATE_X] - wx), k * (u[Q.RATE_Y] - wy), k * (u[Q.RATE_Z] - wz)]


def rk4(p: Params, x, u, dt):
    k1 = derivative(p, x, u)
    k2 = derivative(p, [a + 0.5 * dt * b for a, b in zip(x, k1)], u)
    k3 = derivative(p, [a + 0.5 * dt * b for a, b in zip(x, k2)], u)
    k4 = derivative(p, [a + dt * b for a, b in zip(x, k3)], u)
    y = [a + dt / 6.0 * (b + 2.0 * c + 2.0 * d + e) for a, b, c, d, e in zip(x, k1, k2, k3, k4)]
    n = math.sqrt(y[Q.QW] ** 2 + y[Q.QX] ** 2 + y[Q.QY] ** 2 + y[Q.QZ] ** 2)
    for i in range(Q.QW, Q.QZ + 1):
        y[i] /= n
    return y


def yaw_of(x):
    qw, qx, qy, qz = x[Q.QW], x[Q.QX], x[Q.QY], x[Q.QZ]
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


class Plant:
    """The truth: state, applied command, ground contact. Touching down faster than
    crash_speed, or tilted more than 45 degrees, is a crash."""

    def __init__(self, params: Params, start, yaw=0.0, crash_speed=2.0):
        self.p = params
        self.x = [start[0], start[1], start[2], 0.0, 0.0, 0.0,
                  math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2), 0.0, 0.0, 0.0]
        self.u = [0.0, 0.0, 0.0, 0.0]
        self.on_ground = start[2] <= 0.0
        self.crash_speed = crash_speed
        self.crashed = None  # reason

    def saturate(self, u):
        r = self.p.max_body_rate
        return [min(max(u[Q.THRUST], 0.0), self.p.max_thrust)] + [min(max(c, -r), r) for c in u[Q.BODY_RATES]]

    def step(self, dt):
        x = self.x
        u = self.u
        if self.on_ground:
            bz = 1.0 - 2.0 * (x[Q.QX] ** 2 + x[Q.QY] ** 2)
            if u[Q.THRUST] * bz <= self.p.mass * self.p.gravity:
                return  # resting: the ground carries the weight
            self.on_ground = False
        y = rk4(self.p, x, u, dt)
        if y[Q.PZ] < 0.0:
            tilt_cos = 1.0 - 2.0 * (y[Q.QX] ** 2 + y[Q.QY] ** 2)
            if -y[Q.VZ] > self.crash_speed or tilt_cos < math.cos(math.radians(45)):
                self.crashed = f"ground at {-y[Q.VZ]:.2f} m/s, tilt {math.degrees(math.acos(max(-1, min(1, tilt_cos)))):.0f} deg"
            yaw = yaw_of(y)
            y = [y[Q.PX], y[Q.PY], 0.0, 0.0, 0.0, 0.0, math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2), 0.0, 0.0, 0.0]
            self.on_ground = True
        self.x = y
