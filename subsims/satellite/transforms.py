"""Coupling transforms of the satellite (spec §4.3 RF-C ``coupler``, §5.2 RF-D ``coupler2``/``coupler3``).

Vectorised over samples: ``f(*sources (n, size_i), **params) -> (n, size_out)``. The DCM is eq. 15's
A(phi) = R1(phi_x) R2(phi_y) R3(phi_z), inertial -> body (``dcm321``); body -> inertial is A^T.

Body and geometric axes are parallel (paper fig. 3), so body-frame force components are the geometric ones.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from subsims.numerics import dcm321_batch
from subsims.satellite.constants import R_CM, REARTH_KM

_F8 = np.dtype(np.float64)


def _rows(x: np.ndarray, what: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 1:
        a = a.reshape(1, -1)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{what} must have shape (n, 3), got {np.shape(x)}")
    return a


def _pair(a: np.ndarray, b: np.ndarray, what_a: str, what_b: str) -> tuple[np.ndarray, np.ndarray]:
    # fast path: two float64 (n, 3) arrays (a coupling's signals) are what _rows would return unchanged
    if (type(a) is np.ndarray and type(b) is np.ndarray and a.dtype == _F8 and b.dtype == _F8
            and a.shape == b.shape and a.shape[1:] == (3,)):
        return a, b
    a, b = _rows(a, what_a), _rows(b, what_b)
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"{what_a} has {a.shape[0]} samples but {what_b} has {b.shape[0]}")
    return a, b


_last_dcm: tuple[bytes, np.ndarray] = (b"", np.empty((0, 3, 3)))


def _dcm(phi: np.ndarray) -> np.ndarray:
    """dcm321_batch(phi), remembered for the last phi: a stage rotates three signals by the same angles."""
    global _last_dcm
    key = phi.tobytes()
    if key != _last_dcm[0]:
        _last_dcm = (key, dcm321_batch(phi))
    return _last_dcm[1]


def body_to_inertial(vec_b: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """A(phi)^T v_b: e.g. aero force body -> inertial for the orbit (coupler / coupler3: tran3 + matvec)."""
    v, p = _pair(vec_b, phi, "vec_b", "phi")
    return np.einsum("nji,nj->ni", _dcm(p), v)


def inertial_to_body(vec_i: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """A(phi) v_i: orbit radius / velocity inertial -> body for the aerodynamics (coupler / coupler2)."""
    v, p = _pair(vec_i, phi, "vec_i", "phi")
    return np.einsum("nij,nj->ni", _dcm(p), v)


_CROSS_R = np.array([[1, 2, 0], [2, 0, 1]])  # a x b = a[_CROSS_R[0]] b[_CROSS_F[0]] - a[_CROSS_R[1]] b[_CROSS_F[1]]
_CROSS_F = np.array([[2, 0, 1], [1, 2, 0]])


def torque_to_cm(torque: np.ndarray, force: np.ndarray, r_cm: Sequence[float] = R_CM,
                 physical: bool = False) -> np.ndarray:
    """Aero torque about the c.m. from the torque about the geometric origin and the force acting there.

    ``physical=False`` (default): the listings' T + r_cm x F (coupler, coupler3, rku sub), to match the
    paper's runs. ``physical=True``: eq. 21, T - r_cm x F, the correct moment about the c.m.
    ``r_cm``: c.m. in geometric body coordinates (m), paper (1.0, 0.1, 0.1).
    """
    t, f = _pair(torque, force, "torque", "force")
    r = np.asarray(r_cm, dtype=np.float64)
    if r.shape != (3,):
        raise ValueError(f"parameter 'r_cm' must be 3 numbers, got {r_cm!r}")
    # aero.model.torque_about_cm on all columns at once: r_cm x F = r[1,2,0] f[2,0,1] - r[2,0,1] f[1,2,0] (the
    # same products and differences, operands in the same order, as cross3), then T + or - it
    rf = r.take(_CROSS_R) * f.take(_CROSS_F, axis=1)  # (n, 2, 3)
    rxf = rf[:, 0] - rf[:, 1]
    return t - rxf if physical else t + rxf


def limit_angles(phi: np.ndarray) -> np.ndarray:
    """Output range limiting (rku_out: dcm321 then dcmang321, all three angles jointly): the unlimited
    state angles -> phi_x, phi_z in (-pi, pi], phi_y in [-pi/2, pi/2], same attitude. rad -> rad."""
    a = dcm321_batch(_rows(phi, "phi"))
    phi_y = np.arctan2(-a[:, 0, 2], np.hypot(a[:, 0, 0], a[:, 0, 1]))
    return np.column_stack([np.arctan2(a[:, 1, 2], a[:, 2, 2]), phi_y, np.arctan2(a[:, 0, 1], a[:, 0, 0])])


def altitude_km(radius: np.ndarray, rearth_km: float = REARTH_KM) -> np.ndarray:
    """rfc_out/rku_out altitude: |R|/1000 - rearth (km), shape (n, 1)."""
    return np.linalg.norm(_rows(radius, "radius"), axis=1, keepdims=True) / 1000.0 - rearth_km
