"""Constrained modal analysis (report chapter 5; spec §2.4, AT-5, AT-16)."""

import warnings

import numpy as np
import pytest

from subsims.flexbody import modal
from subsims.flexbody.config import build
from subsims.flexbody.vehicle import SAMPLE_VEHICLE

MASSES = np.array(SAMPLE_VEHICLE["masses"], float)

# spec §2.4 closed forms: bending w^2 = (6EI/(7 m L^3))(10 -+ sqrt 86), axial (EA/(m L))(2 -+ sqrt 2), each twice
L, EIX, EIZ, EA = 10.0, 1.0e4, 4.0e4, 1.0e6
BEND = np.array([10.0 - np.sqrt(86.0), 10.0 + np.sqrt(86.0)]) * 6.0 / (7.0 * L**3)
AXIAL = EA / L * np.array([2 - 2**0.5, 2 + 2**0.5])
CLOSED_FORM = np.sort(np.repeat(np.concatenate([BEND * EIX, BEND * EIZ, AXIAL]), 2))
SPEC_HZ = [0.3971267, 0.7942535, 2.0456360, 4.0912721, 38.520311, 92.996258]


def sample_modes():
    K = modal.boom_stiffness(4, SAMPLE_VEHICLE["booms"], L, EIX, EIZ, EA)
    return K, *modal.constrained_modes(K, MASSES)


def test_boom_frequencies_equal_closed_form():
    K, omega2, Phi = sample_modes()
    np.testing.assert_allclose(omega2, CLOSED_FORM, rtol=1e-9)
    np.testing.assert_allclose(modal.frequencies_hz(omega2)[::2], SPEC_HZ, rtol=2e-7)  # spec table, 8 digits
    # the spec's closed form is the general two-station root for m_tip = m_mid / 2
    np.testing.assert_allclose(modal.two_station_boom_omega2(1.0, 0.5, L, EIX, False), BEND * EIX, rtol=1e-12)


def test_modes_mass_normalized_and_K_orthogonal():
    K, omega2, Phi = sample_modes()
    M = modal.particle_mass_matrix(MASSES)
    np.testing.assert_allclose(Phi.T @ M @ Phi, np.eye(12), atol=1e-10)
    np.testing.assert_allclose(Phi.T @ K @ Phi, np.diag(omega2), atol=1e-10 * omega2.max())


def test_repeated_pairs_are_single_direction_bending():
    """Modes 1-2 are x-bending (boom A and B), 3-4 z-bending: no other components."""
    _, _, Phi = sample_modes()
    x_dofs, z_dofs = np.arange(0, 12, 3), np.arange(2, 12, 3)
    other = np.setdiff1d(np.arange(12), x_dofs)
    assert np.abs(Phi[other][:, :2]).max() < 1e-12
    other = np.setdiff1d(np.arange(12), z_dofs)
    assert np.abs(Phi[other][:, 2:4]).max() < 1e-12


@pytest.mark.parametrize("n", [1, 3, 7])
def test_spring_chain_frequencies(n):
    """Fixed-free chain of n equal masses m and springs k: w_j = 2 sqrt(k/m) sin((2j - 1) pi / (2 (2n + 1)))."""
    k, m = 3.0, 0.7
    k1 = 2 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    k1[-1, -1] = 1.0
    K = np.kron(k * k1, np.eye(3))  # each particle moves in x, y, z alike
    omega2, Phi = modal.constrained_modes(K, np.full(n, m))
    j = np.arange(1, n + 1)
    exact = (2 * np.sqrt(k / m) * np.sin((2 * j - 1) * np.pi / (2 * (2 * n + 1)))) ** 2
    np.testing.assert_allclose(omega2, np.repeat(exact, 3), rtol=1e-10)


def test_truncation_keeps_lowest_and_warns_on_split_pair():
    _, omega2, Phi = sample_modes()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        w2, P = modal.truncate(omega2, Phi, 4)
    np.testing.assert_array_equal(w2, omega2[:4])
    assert P.shape == (12, 4)
    with pytest.warns(modal.ModalWarning, match="splits a degenerate eigenvalue pair"):
        modal.truncate(omega2, Phi, 3)


def test_supplied_modes_match_stiffness_route():
    _, omega2, Phi = sample_modes()
    a = build({"n_modes": 4}).model
    b = build({"n_modes": 4, "omega2": omega2.tolist(), "Phi": Phi.tolist()}).model
    np.testing.assert_allclose(b.K_eta, a.K_eta, rtol=1e-12)
    with pytest.raises(ValueError, match="mass-normalized"):
        build({"omega2": omega2.tolist(), "Phi": (2 * Phi).tolist()})


@pytest.mark.parametrize(
    "params, match",
    [
        ({"I_b": np.zeros((3, 3)).tolist(), "s": [0, 0, 0]}, "I_b"),
        ({"K": (np.eye(12) + np.triu(np.ones((12, 12)), 1)).tolist()}, "symmetric"),
        ({"K": (np.eye(12) - 2 * np.eye(12, k=0) * (np.arange(12) == 5)).tolist()}, "positive definite"),
        ({"n_modes": 13}, "n_modes"),
        ({"masses": [1.0, -0.5, 1.0, 0.5]}, "masses"),
        ({"mass_order": 4}, "mass_order"),
        ({"n_mode": 2}, "unknown"),
    ],
)
def test_invalid_parameters_rejected(params, match):
    with pytest.raises(ValueError, match=match):
        build(params)
