"""ENU/FLU truth -> MAVLink's NED/FRD, written with rotation matrices: a second, independent
implementation of drivers/mavlink/mppi_mavlink/frames.py (which composes quaternions), so
the end-to-end tests do not check the bridge's conversion against itself.

    R_ned_frd = A R_enu_flu B,  A = [[0,1,0],[1,0,0],[0,0,-1]],  B = diag(1,-1,-1)."""
from __future__ import annotations

import math

from mppi_mavlink.layout import QuadrotorRate as Q

A = ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, -1.0))
B = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))


def matmul(a, b):
    return tuple(tuple(sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)) for i in range(3))


def matvec(a, v):
    return tuple(sum(a[i][k] * v[k] for k in range(3)) for i in range(3))


def transpose(a):
    return tuple(tuple(a[j][i] for j in range(3)) for i in range(3))


def quat_to_matrix(q):
    w, x, y, z = q
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


def matrix_to_quat(m):
    """Shepperd's method; w >= 0."""
    tr = m[0][0] + m[1][1] + m[2][2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = (0.25 * s, (m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s)
    elif m[0][0] > m[1][1] and m[0][0] > m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[0][0] - m[1][1] - m[2][2])
        q = ((m[2][1] - m[1][2]) / s, 0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s)
    elif m[1][1] > m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[1][1] - m[0][0] - m[2][2])
        q = ((m[0][2] - m[2][0]) / s, (m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m[2][2] - m[0][0] - m[1][1])
        q = ((m[1][0] - m[0][1]) / s, (m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s)
    n = math.sqrt(sum(c * c for c in q))
    sgn = 1.0 if q[0] >= 0 else -1.0
    return tuple(sgn * c / n for c in q)


def state_to_ned(x):
    """13-state ENU/FLU truth -> (p_ned, v_ned, q_ned_frd, v_body_frd, w_frd)."""
    r_enu = quat_to_matrix(x[Q.QUAT])
    r_ned = matmul(matmul(A, r_enu), B)
    p = matvec(A, x[Q.POS])
    v = matvec(A, x[Q.VEL])
    v_body = matvec(transpose(r_ned), v)
    w = matvec(B, x[Q.RATES])
    return p, v, matrix_to_quat(r_ned), v_body, w
