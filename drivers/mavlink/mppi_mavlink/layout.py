"""The state and command layouts of mppid's models, named as in C++ (core/include/mppi/models/*.hpp).

vehicle_state_t.x and command_t.u carry these vectors; index them by name, never by number:

    from mppi_mavlink.layout import QuadrotorRate as Q
    p, q, thrust = x[Q.POS], x[Q.QUAT], u[Q.THRUST]

Each class also lists its state names (STATE) and command names (COMMAND) in C++'s enum order;
test/mavlink/test_layout.py holds both to the headers (where C++ names the commands)
and to the constants here.
"""
from __future__ import annotations


class QuadrotorRate:
    """quadrotor_rate.hpp: position, velocity (world ENU), attitude quaternion (w, x, y, z: body
    FLU -> ENU), body rates (FLU); commands: collective thrust (N) and body-rate setpoints (rad/s)."""
    NAME = "quadrotor_rate"
    STATE = ("PX", "PY", "PZ", "VX", "VY", "VZ", "QW", "QX", "QY", "QZ", "WX", "WY", "WZ")
    COMMAND = ("THRUST", "RATE_X", "RATE_Y", "RATE_Z")
    PX, PY, PZ, VX, VY, VZ, QW, QX, QY, QZ, WX, WY, WZ = range(13)
    THRUST, RATE_X, RATE_Y, RATE_Z = range(4)
    POS = slice(PX, PZ + 1)
    VEL = slice(VX, VZ + 1)
    QUAT = slice(QW, QZ + 1)
    RATES = slice(WX, WZ + 1)
    BODY_RATES = slice(RATE_X, RATE_Z + 1)   # the command's body-rate setpoints


class Quadrotor:
    """quadrotor.hpp: position, velocity, ZXY Euler angles, body rates, motor speeds (rpm);
    commands: the four desired motor speeds."""
    NAME = "quadrotor"
    STATE = ("PX", "PY", "PZ", "VX", "VY", "VZ", "ROLL", "PITCH", "YAW", "WX", "WY", "WZ", "M1", "M2", "M3", "M4")
    COMMAND = ("M1_DES", "M2_DES", "M3_DES", "M4_DES")
    PX, PY, PZ, VX, VY, VZ, ROLL, PITCH, YAW, WX, WY, WZ, M1, M2, M3, M4 = range(16)
    M1_DES, M2_DES, M3_DES, M4_DES = range(4)
    POS = slice(PX, PZ + 1)
    VEL = slice(VX, VZ + 1)
    MOTORS = slice(M1, M4 + 1)


class Racecar:
    """racecar.hpp: x, y, heading psi, slip beta, body velocities vx, vy, yaw rate r, steering
    delta, drive force Fx; commands: steering and drive."""
    NAME = "racecar"
    STATE = ("X", "Y", "PSI", "BETA", "VX", "VY", "R", "DELTA", "FX")
    COMMAND = ("STEER", "DRIVE")
    X, Y, PSI, BETA, VX, VY, R, DELTA, FX = range(9)
    STEER, DRIVE = range(2)


class Cartpole:
    """cartpole.hpp: cart x, its speed, pole angle theta (0 = down), its rate, motor force;
    command: the desired force."""
    NAME = "cartpole"
    STATE = ("X", "XDOT", "THETA", "THETADOT", "FORCE")
    COMMAND = ("FORCE_DES",)
    X, XDOT, THETA, THETADOT, FORCE = range(5)
    FORCE_DES = 0


MODELS = (QuadrotorRate, Quadrotor, Racecar, Cartpole)
