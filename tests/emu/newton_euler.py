"""An independent rigid-body reference for the plant tests: recursive Newton–Euler in world axes.

It shares nothing with MuJoCo or the MJCF builder except the physical parameters
(:class:`~kukavarproxy_emu.plant.params.Bodies`): its own D-H chain, its own recursion. Link
j's body frame is the D-H frame j-1 turned by the joint, ``B_j = F_{j-1}·Rz(sign_j·q_j)``;
mass, centre of mass and inertia are given in it.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from kukavarproxy_emu.plant.frames import dh_matrix, frame_matrix
from kukavarproxy_emu.plant.mjcf import GRAVITY, Payload
from kukavarproxy_emu.plant.params import Bodies

FloatArray = npt.NDArray[np.float64]


def _rz(rad: float) -> FloatArray:
    c, s = np.cos(rad), np.sin(rad)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def body_frames(b: Bodies, q_rad: FloatArray) -> tuple[FloatArray, FloatArray]:
    """World frames of the six link bodies (mm) and of the flange, at ``q`` (rad)."""
    frames = np.empty((6, 4, 4))
    f_prev = np.eye(4)  # D-H frame j-1
    for j in range(6):
        frames[j] = f_prev @ _rz(b.sign[j] * q_rad[j])
        f_prev = frames[j] @ dh_matrix(b.a[j], b.alpha[j], b.d[j], b.offset[j])
    return frames, f_prev @ b.flange


def inverse_dynamics(
    b: Bodies,
    q: FloatArray,
    qd: FloatArray,
    qdd: FloatArray,
    *,
    armature: FloatArray | None = None,
    payload: Payload | None = None,
    tool: FloatArray | None = None,
    wrench_on_robot: FloatArray | None = None,
) -> FloatArray:
    """Joint torques (Nm, about the +KUKA axes) for motion ``q, qd, qdd`` (rad, rad/s, rad/s²)
    under gravity, with an external wrench [F (N), M (Nm)] acting *on* the robot at the TCP."""
    frames, flange = body_frames(b, q)
    rot = frames[:, :3, :3]
    org = frames[:, :3, 3] / 1000.0
    z = rot[:, :, 2] * b.sign[:, None]
    com = org + np.einsum("jik,jk->ji", rot, b.com / 1000.0)
    inertia = [
        rot[j] @ b.inertia_axes[j] @ np.diag(b.inertia[j]) @ b.inertia_axes[j].T @ rot[j].T
        for j in range(6)
    ]
    w = np.zeros(3)
    dw = np.zeros(3)
    acc_origin = np.array([0.0, 0.0, GRAVITY])  # gravity as an upward base acceleration
    prev_org = np.zeros(3)
    f_link, n_link = [], []
    for j in range(6):
        acc_origin = (
            acc_origin
            + np.cross(dw, org[j] - prev_org)
            + np.cross(w, np.cross(w, org[j] - prev_org))
        )
        dw = dw + z[j] * qdd[j] + np.cross(w, z[j] * qd[j])
        w = w + z[j] * qd[j]
        prev_org = org[j]
        r = com[j] - org[j]
        a_com = acc_origin + np.cross(dw, r) + np.cross(w, np.cross(w, r))
        f = b.mass[j] * a_com
        n = inertia[j] @ dw + np.cross(w, inertia[j] @ w) + np.cross(r, f)  # about the origin
        f_link.append(f)
        n_link.append(n)
    if payload is not None:  # a body welded to link 6
        cm = flange @ frame_matrix(payload.cm)
        r = cm[:3, 3] / 1000.0 - org[5]
        i_world = cm[:3, :3] @ np.diag(payload.inertia) @ cm[:3, :3].T
        a_com = acc_origin + np.cross(dw, r) + np.cross(w, np.cross(w, r))
        f = payload.mass * a_com
        f_link[5] = f_link[5] + f
        n_link[5] = n_link[5] + i_world @ dw + np.cross(w, i_world @ w) + np.cross(r, f)
    if wrench_on_robot is not None:
        tcp = flange @ (tool if tool is not None else np.eye(4))
        r = tcp[:3, 3] / 1000.0 - org[5]
        fe, me = wrench_on_robot[:3], wrench_on_robot[3:]
        f_link[5] = f_link[5] - fe
        n_link[5] = n_link[5] - me - np.cross(r, fe)
    tau = np.zeros(6)
    f_next, n_next, org_next = np.zeros(3), np.zeros(3), org[5]
    for j in reversed(range(6)):
        n_total = n_link[j] + n_next + np.cross(org_next - org[j], f_next)
        f_next = f_link[j] + f_next
        n_next, org_next = n_total, org[j]
        tau[j] = z[j] @ n_total
    if armature is not None:
        tau = tau + armature * qdd
    return tau


def tcp_jacobian(b: Bodies, q: FloatArray, tool: FloatArray | None = None) -> FloatArray:
    """Geometric Jacobian (6×6, m/rad and rad/rad) of the TCP in world axes."""
    frames, flange = body_frames(b, q)
    tcp = (flange @ (tool if tool is not None else np.eye(4)))[:3, 3] / 1000.0
    jac = np.zeros((6, 6))
    for j in range(6):
        axis = frames[j, :3, 2] * b.sign[j]
        jac[:3, j] = np.cross(axis, tcp - frames[j, :3, 3] / 1000.0)
        jac[3:, j] = axis
    return jac
