"""Attitude kinematics (Storch & Gates, chapter 7) held without a singularity.

The report integrates 1-2-3 Euler angles with (7-2), singular at cos(theta_2) = 0, a point its own sample
run passes at t = 7, 25 and 43 s. Here the attitude is a unit quaternion (scalar first, body -> inertial,
i.e. the report's R^14); the Euler angles are only *reported*, extracted from the direction cosines on the
branch nearest the previous report so that they run continuously like the report's integrated angles.
"""

from __future__ import annotations

import numpy as np

from subsims import numerics
from subsims.numerics import rotation321

cross, skew = numerics.cross, numerics.skew  # a x b and a~, kept where the flexbody's users look

GIMBAL_EPS = 1e-9  # |cos theta_2| below which theta_1 / theta_3 are split by holding theta_1


def euler123_to_dcm(theta: np.ndarray) -> np.ndarray:
    """R^14 = R^12(theta_1) R^23(theta_2) R^34(theta_3), body -> inertial (7-1): these active rotations are the
    passive 3-2-1 matrix (Nixon eq. 15, ``subsims.numerics.rotation321``) of the negated angles."""
    return np.array(rotation321(-np.sin(theta), np.cos(theta)))


def euler_rates(theta: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Euler rates from body rates, theta_dot = Gamma omega (7-2); singular at cos(theta_2) = 0."""
    c2, s2 = np.cos(theta[1]), np.sin(theta[1])
    c3, s3 = np.cos(theta[2]), np.sin(theta[2])
    gamma = np.array([[c3 / c2, -s3 / c2, 0.0], [s3, c3, 0.0], [-c3 * s2 / c2, s3 * s2 / c2, 1.0]])
    return gamma @ omega


def quat_to_dcm(q: np.ndarray) -> np.ndarray:
    """Direction cosines (body -> inertial) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array(
        [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
        ]
    )


def dcm_to_quat(C: np.ndarray) -> np.ndarray:
    """Unit quaternion (w >= 0) of a rotation matrix, by the largest-pivot (Shepperd) rule."""
    tr = np.trace(C)
    pivots = np.array([tr, C[0, 0], C[1, 1], C[2, 2]])
    k = int(np.argmax(pivots))
    if k == 0:
        w = 0.5 * np.sqrt(1.0 + tr)
        q = np.array([w, (C[2, 1] - C[1, 2]) / (4 * w), (C[0, 2] - C[2, 0]) / (4 * w), (C[1, 0] - C[0, 1]) / (4 * w)])
    elif k == 1:
        x = 0.5 * np.sqrt(1.0 + 2 * C[0, 0] - tr)
        q = np.array([(C[2, 1] - C[1, 2]) / (4 * x), x, (C[0, 1] + C[1, 0]) / (4 * x), (C[0, 2] + C[2, 0]) / (4 * x)])
    elif k == 2:
        y = 0.5 * np.sqrt(1.0 + 2 * C[1, 1] - tr)
        q = np.array([(C[0, 2] - C[2, 0]) / (4 * y), (C[0, 1] + C[1, 0]) / (4 * y), y, (C[1, 2] + C[2, 1]) / (4 * y)])
    else:
        z = 0.5 * np.sqrt(1.0 + 2 * C[2, 2] - tr)
        q = np.array([(C[1, 0] - C[0, 1]) / (4 * z), (C[0, 2] + C[2, 0]) / (4 * z), (C[1, 2] + C[2, 1]) / (4 * z), z])
    q = q if q[0] >= 0 else -q
    return q / np.linalg.norm(q)


def quat_rate(q: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """q_dot = 1/2 q (x) (0, omega), omega in body axes."""
    w, x, y, z = q
    p, r, s = omega
    return 0.5 * np.array([-x * p - y * r - z * s, w * p + y * s - z * r, w * r + z * p - x * s, w * s + x * r - y * p])


def _nearest(angle: float, ref: float) -> float:
    """angle + 2 pi k closest to ref."""
    return angle + 2.0 * np.pi * np.round((ref - angle) / (2.0 * np.pi))


def euler123_from_dcm(C: np.ndarray, ref: np.ndarray | None = None) -> np.ndarray:
    """The report's 1-2-3 angles of C = R^14 (7-1).

    Without ``ref``: the canonical set, theta_2 in [-pi/2, pi/2], theta_1, theta_3 in (-pi, pi].
    With ``ref``: of the two sets (theta_1, theta_2, theta_3) and (theta_1 + pi, pi - theta_2, theta_3 + pi),
    each shifted by multiples of 2 pi, the one nearest ``ref``, so angles run on continuously through
    cos(theta_2) = 0 as the report's integrated angles do (theta_2 reaches 620 deg in its sample run).
    At gimbal lock (|cos theta_2| < GIMBAL_EPS) only theta_1 +- theta_3 is defined: theta_1 is held at ref.
    """
    s2 = float(np.clip(C[0, 2], -1.0, 1.0))
    base = np.arcsin(s2)
    if ref is None:
        c2 = np.cos(base)
        return np.array([np.arctan2(-C[1, 2] / c2, C[2, 2] / c2), base, np.arctan2(-C[0, 1] / c2, C[0, 0] / c2)])
    best, best_d = None, np.inf
    for th2 in (base, np.pi - base):
        th2 = _nearest(th2, ref[1])
        c2 = np.cos(th2)
        if abs(c2) > GIMBAL_EPS:
            th1 = np.arctan2(-C[1, 2] / c2, C[2, 2] / c2)
            th3 = np.arctan2(-C[0, 1] / c2, C[0, 0] / c2)
        else:  # C[1,0] = sin(th3 + s th1), C[1,1] = cos(th3 + s th1) with s = sign(sin th2)
            sgn = 1.0 if np.sin(th2) > 0 else -1.0
            th1 = ref[0]
            th3 = np.arctan2(C[1, 0], C[1, 1]) - sgn * th1
        cand = np.array([_nearest(th1, ref[0]), th2, _nearest(th3, ref[2])])
        d = float(np.sum((cand - ref) ** 2))
        if d < best_d:
            best, best_d = cand, d
    return best


def euler_zyx_from_dcm(C: np.ndarray) -> np.ndarray:
    """Nixon's z-y-x angles (phi_x, phi_y, phi_z) of the same body -> inertial C = Rz Ry Rx (spec §4.6)."""
    phi_y = -np.arcsin(np.clip(C[2, 0], -1.0, 1.0))
    return np.array([np.arctan2(C[2, 1], C[2, 2]), phi_y, np.arctan2(C[1, 0], C[0, 0])])
