"""Frames: the project's (world ENU, body FLU) against MAVLink's (local NED, body FRD).

The project (core/include/mppi/models/quadrotor_rate.hpp): world x east, y north, z up;
body x forward, y left, z up (the thrust axis); q = (w, x, y, z) rotates body vectors into
the world (v_world = R(q) v_body); body rates in the body frame.
MAVLink (LOCAL_POSITION_NED, ATTITUDE_QUATERNION, ODOMETRY, SET_ATTITUDE_TARGET): world x
north, y east, z down; body x forward, y right, z down; q = (w, x, y, z) body FRD to NED.

Vectors
    world: (x, y, z)_NED = (y, x, -z)_ENU       the same map both ways (A = A^T = A^-1)
    body:  (x, y, z)_FRD = (x, -y, -z)_FLU      the same map both ways (B = B^T = B^-1)
    so positions and velocities swap x/y and negate z; body rates (p, q, r) negate q and r.

Attitude
    R_ned_frd = A R_enu_flu B,   A = [[0,1,0],[1,0,0],[0,0,-1]],  B = diag(1,-1,-1).
    A is a rotation by pi about (1,1,0)/sqrt2: q_A = (0, 1/sqrt2, 1/sqrt2, 0);
    B is a rotation by pi about x:               q_B = (0, 1, 0, 0).
    q_ned_frd = q_A (x) q_enu_flu (x) q_B, and back q_enu_flu = q_A* (x) q_ned_frd (x) q_B*.
    Written out: q_ned_frd = ((w+z), (x+y), (x-y), (w-z)) / sqrt2 up to sign, and the inverse
    is the same formula (the map is an involution on rotations).
    A quaternion and its negative are the same rotation; results are returned with w >= 0.
    Heading: yaw_ned = pi/2 - yaw_enu (level, facing east: yaw_enu 0, yaw_ned +90 deg).
"""
from __future__ import annotations

import math

_S = math.sqrt(0.5)
Q_ENU_TO_NED = (0.0, _S, _S, 0.0)
Q_FLU_TO_FRD = (0.0, 1.0, 0.0, 0.0)


def quat_mul(a, b):
    """Hamilton product a (x) b, quaternions (w, x, y, z)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def quat_conj(q):
    return (q[0], -q[1], -q[2], -q[3])


def quat_normalize(q):
    """Unit quaternion with w >= 0; raises ValueError for a zero or non-finite one."""
    n = math.sqrt(sum(c * c for c in q))
    if not math.isfinite(n) or n < 1e-9:
        raise ValueError(f"not a rotation quaternion: {tuple(q)}")
    s = 1.0 / n if q[0] >= 0.0 else -1.0 / n
    return tuple(c * s for c in q)


def tilt_deg(q) -> float:
    """The angle between the body z axis and the vertical, degrees, of a (w, x, y, z)
    quaternion (either frame pair: NED/FRD or ENU/FLU)."""
    _, x, y, _ = q
    return math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (x * x + y * y)))))


def enu_to_ned(v):
    """World vector (position, velocity) ENU -> NED; also NED -> ENU (self-inverse)."""
    return (v[1], v[0], -v[2])


ned_to_enu = enu_to_ned


def flu_to_frd(v):
    """Body vector (body rates, forces) FLU -> FRD; also FRD -> FLU (self-inverse)."""
    return (v[0], -v[1], -v[2])


frd_to_flu = flu_to_frd


def q_enu_flu_to_ned_frd(q):
    """Attitude body FLU -> world ENU  to  body FRD -> world NED."""
    return quat_normalize(quat_mul(quat_mul(Q_ENU_TO_NED, q), Q_FLU_TO_FRD))


def q_ned_frd_to_enu_flu(q):
    """Attitude body FRD -> world NED  to  body FLU -> world ENU."""
    return quat_normalize(quat_mul(quat_mul(quat_conj(Q_ENU_TO_NED), q), quat_conj(Q_FLU_TO_FRD)))


def yaw_enu_to_ned(yaw):
    """Heading about the vertical: ENU (from east, counter-clockwise) to NED (from north, clockwise)."""
    return math.atan2(math.cos(yaw), math.sin(yaw))  # = pi/2 - yaw, wrapped to (-pi, pi]


yaw_ned_to_enu = yaw_enu_to_ned
