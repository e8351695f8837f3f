"""Coupling transforms between the flexbody family and the rigid attitude subsim (``subsims.attitude``).

Vectorised (cosim.transforms contract): each source is the (n, size) samples of one output over an interval.

Conventions (spec §4.6). Both subsims use body axes parallel to each other (the flexbody's body frame; give the
attitude subsim the composite inertia in those axes) and are unit-agnostic: the "N m" labels of the attitude subsim's
ports are labels only, so torques and rates pass unchanged (identity couplings) in slug-ft-lbf-s as well. Only the
Euler angles differ:

- flexbody / controller: the report's 1-2-3 angles theta, body->inertial C = Rx(theta_1) Ry(theta_2) Rz(theta_3);
- attitude subsim: Nixon's z-y-x angles phi, inertial->body A = R1(phi_x) R2(phi_y) R3(phi_z) (passive), C = A^T.
"""

from __future__ import annotations

import numpy as np

from subsims.flexbody.kinematics import euler123_from_dcm
from subsims.numerics import dcm321_batch


def zyx_to_euler123(phi: np.ndarray) -> np.ndarray:
    """The report's 1-2-3 angles (rad) of the attitude given by the attitude subsim's z-y-x angles ``phi`` (rad).

    theta_2 = asin(C13), theta_1 = atan2(-C23, C33), theta_3 = atan2(-C12, C11) with C = A(phi)^T; the set is
    the canonical one at the first sample and continuous along the interval after it (the flexbody controller
    wraps its angle errors to (-pi, pi], so the 2 pi branch does not matter to it).
    """
    C = np.transpose(dcm321_batch(phi), (0, 2, 1))
    out = np.empty((C.shape[0], 3))
    ref = None
    for k in range(C.shape[0]):
        ref = out[k] = euler123_from_dcm(C[k], ref=ref)
    return out


def euler123_to_zyx(theta: np.ndarray) -> np.ndarray:
    """Inverse of :func:`zyx_to_euler123`: phi_x = atan2(C32, C33), phi_y = -asin(C31), phi_z = atan2(C21, C11)."""
    from subsims.flexbody.kinematics import euler123_to_dcm

    theta = np.asarray(theta, dtype=np.float64).reshape(-1, 3)
    C = np.array([euler123_to_dcm(th) for th in theta])
    return np.stack([np.arctan2(C[:, 2, 1], C[:, 2, 2]), -np.arcsin(np.clip(C[:, 2, 0], -1.0, 1.0)),
                     np.arctan2(C[:, 1, 0], C[:, 0, 0])], axis=1)
