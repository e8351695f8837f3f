"""Constrained (cantilever) modes of the particle appendage and their truncation (Storch & Gates, chapter 5).

Also the spec's stiffness builder for massless cantilevered booms (spec §2.4 [EXT]): the report reads its
stiffness matrix from FORTRAN unit 8 and never prints it, so the sample vehicle needs a documented choice.

Ordering of the 3n physical deflections (report L127): q = (q_x^1, q_y^1, q_z^1, q_x^2, ..., q_z^n).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

CLUSTER_RTOL = 1e-8  # spec §1.6: |w2[t] - w2[t-1]| <= 1e-8 w2[t-1] means t cuts a repeated eigenvalue


class ModalWarning(UserWarning):
    """The retained modes split a repeated eigenvalue: the retained subspace is arbitrary."""


def particle_mass_matrix(masses: np.ndarray) -> np.ndarray:
    """M = diag(m^1, ..., m^n), m^i = m_i E_3 (3n x 3n)."""
    return np.diag(np.repeat(np.asarray(masses, dtype=np.float64), 3))


def check_stiffness(K: np.ndarray, n_particles: int) -> np.ndarray:
    """Return K as float64 (3n x 3n) after checking size, symmetry and positive definiteness (report L133, L417)."""
    K = np.asarray(K, dtype=np.float64)
    dof = 3 * n_particles
    if K.shape != (dof, dof):
        raise ValueError(f"stiffness K must be {dof}x{dof} for {n_particles} particles, got {K.shape}")
    scale = float(np.max(np.abs(K))) if K.size else 0.0
    if not np.all(np.isfinite(K)) or scale == 0.0:
        raise ValueError("stiffness K must be finite and nonzero")
    if np.max(np.abs(K - K.T)) > 1e-12 * scale:
        raise ValueError("stiffness K must be symmetric (|K - K^T| <= 1e-12 |K|)")
    try:
        np.linalg.cholesky(K)
    except np.linalg.LinAlgError:
        raise ValueError("stiffness K must be positive definite (cantilevered appendage: no rigid modes)") from None
    return K


def constrained_modes(K: np.ndarray, masses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All 3n constrained modes of (K - w^2 M) v = 0 (5-1), solved through the symmetric form (5-2).

    G = M^(-1/2) K M^(-1/2) is symmetric; G W = w^2 W with orthonormal W; v = M^(-1/2) W.
    Returns (omega2 ascending (3n,), Phi (3n, 3n)) with Phi^T M Phi = E and Phi^T K Phi = diag(omega2).
    """
    from scipy.linalg import eigh

    m_dof = np.repeat(np.asarray(masses, dtype=np.float64), 3)
    m_inv_sqrt = 1.0 / np.sqrt(m_dof)
    G = m_inv_sqrt[:, None] * K * m_inv_sqrt[None, :]  # (5-2)
    G = 0.5 * (G + G.T)
    omega2, W = eigh(G)  # ascending, orthonormal columns
    Phi = m_inv_sqrt[:, None] * W  # v = M^(-1/2) W, mass-normalized
    return omega2, Phi


def splits_cluster(omega2: np.ndarray, t: int, rtol: float = CLUSTER_RTOL) -> bool:
    """True when keeping the first t modes cuts through a (numerically) repeated eigenvalue."""
    if t <= 0 or t >= omega2.size:
        return False
    return bool(abs(omega2[t] - omega2[t - 1]) <= rtol * abs(omega2[t - 1]))


def truncate(omega2: np.ndarray, Phi: np.ndarray, t: int) -> tuple[np.ndarray, np.ndarray]:
    """Keep the t lowest modes, q = Phi eta (5-3). Warn when t splits a repeated eigenvalue (spec §1.6)."""
    if not 0 <= t <= omega2.size:
        raise ValueError(f"n_modes must be between 0 and 3n = {omega2.size}, got {t}")
    if splits_cluster(omega2, t):
        warnings.warn(
            f"n_modes = {t} splits a degenerate eigenvalue pair (w2 = {omega2[t - 1]:.9g}): "
            "the retained subspace is arbitrary",
            ModalWarning,
            stacklevel=2,
        )
    return omega2[:t].copy(), Phi[:, :t].copy()


def check_modes(Phi: np.ndarray, omega2: np.ndarray, masses: np.ndarray, tol: float = 1e-9) -> None:
    """Check user-supplied modes: Phi^T M Phi = E to ``tol`` (spec §1.6) and omega2 > 0."""
    m_dof = np.repeat(np.asarray(masses, dtype=np.float64), 3)
    if Phi.ndim != 2 or Phi.shape[0] != m_dof.size or Phi.shape[1] != omega2.size:
        raise ValueError(f"Phi must be {m_dof.size} x {omega2.size}, got {Phi.shape}")
    err = np.max(np.abs(Phi.T @ (m_dof[:, None] * Phi) - np.eye(omega2.size)), initial=0.0)
    if err > tol:
        raise ValueError(f"Phi is not mass-normalized: |Phi^T M Phi - E| = {err:.3g} > {tol:g}")
    if np.any(omega2 <= 0):
        raise ValueError("omega2 must be positive (cantilevered appendage)")


def frequencies_hz(omega2: np.ndarray) -> np.ndarray:
    """The report's printed FHZ = sqrt(w^2) / 6.283185 (here with 2 pi exactly)."""
    return np.sqrt(omega2) / (2.0 * np.pi)


# ---------------------------------------------------------------------------------------------------------
# Spec §2.4 [EXT]: massless uniform Euler-Bernoulli cantilevers, clamped at the bus face.


def cantilever_flexibility(distances: Sequence[float], rigidity: float, axial: bool = False) -> np.ndarray:
    """Flexibility of a clamped massless beam at stations a <= b from the root.

    Transverse: delta(a, b) = a^2 (3b - a) / (6 EI). Axial: delta(a, b) = min(a, b) / EA.
    """
    d = np.asarray(distances, dtype=np.float64)
    a = np.minimum.outer(d, d)
    b = np.maximum.outer(d, d)
    if axial:
        return a / rigidity
    return a * a * (3.0 * b - a) / (6.0 * rigidity)


def boom_stiffness(
    n_particles: int,
    booms: Sequence[Sequence[int]],
    L: float,
    EI_x: float,
    EI_z: float,
    EA: float,
) -> np.ndarray:
    """Global K (3n x 3n) of cantilevered booms along body y (spec §2.4).

    ``booms`` lists each boom's particles by report number (1-based), root to tip; the k-th particle of a
    boom sits k L from the clamp. Deflection along x bends with EI_x, along z with EI_z; along y is axial
    (EA). Booms clamped to the rigid bus do not couple, so K is block-diagonal by boom.
    """
    K = np.zeros((3 * n_particles, 3 * n_particles))
    seen: set[int] = set()
    for boom in booms:
        idx = [int(p) - 1 for p in boom]
        if any(i < 0 or i >= n_particles for i in idx) or seen.intersection(idx):
            raise ValueError(f"boom {list(boom)}: particle numbers must be 1..{n_particles} and used once")
        seen.update(idx)
        dist = L * np.arange(1, len(idx) + 1)
        for axis, (rigidity, axial) in enumerate(((EI_x, False), (EA, True), (EI_z, False))):
            k_axis = np.linalg.inv(cantilever_flexibility(dist, rigidity, axial))
            dofs = [3 * i + axis for i in idx]
            K[np.ix_(dofs, dofs)] = 0.5 * (k_axis + k_axis.T)
    if len(seen) != n_particles:
        raise ValueError(f"every particle must belong to a boom; missing {sorted(set(range(n_particles)) - seen)}")
    return K


def two_station_boom_omega2(m_mid: float, m_tip: float, L: float, rigidity: float, axial: bool) -> np.ndarray:
    """Closed-form constrained w^2 of one boom with two stations (L, 2L): roots of det(K - w^2 M) = 0.

    For the spec masses (m_tip = m_mid/2) these reduce to (6EI/(7 m L^3))(10 -+ sqrt 86) for bending
    and (EA/(m L))(2 -+ sqrt 2) axially (spec §2.4).
    """
    if axial:
        k = rigidity / L * np.array([[2.0, -1.0], [-1.0, 1.0]])
    else:
        k = 6.0 * rigidity / (7.0 * L**3) * np.array([[16.0, -5.0], [-5.0, 2.0]])
    # det([[k11 - w m1, k12], [k12, k22 - w m2]]) = m1 m2 w^2 - (k11 m2 + k22 m1) w + (k11 k22 - k12^2)
    a = m_mid * m_tip
    b = -(k[0, 0] * m_tip + k[1, 1] * m_mid)
    c = k[0, 0] * k[1, 1] - k[0, 1] ** 2
    disc = np.sqrt(b * b - 4.0 * a * c)
    return np.array([(-b - disc) / (2.0 * a), (-b + disc) / (2.0 * a)])
