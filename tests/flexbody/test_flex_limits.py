"""Rigid and infinite-stiffness limits (spec AT-9): NT = 0 is the rigid composite body; scaling the stiffness by s
makes the base motion converge to it as 1/s."""

import numpy as np
import pytest

from subsims.flexbody.kinematics import euler123_to_dcm
from subsims.flexbody.reference import simulate_free

REST = {"R0": [0.0, 0.0, 0.0], "euler123_deg": [0.0, 0.0, 0.0], "V0": [0.0, 0.0, 0.0], "omega_deg_s": [0.0, 0.0, 0.0]}
IZZ, TQ, TF = 641.5833333333334, 10.0, 10.0  # composite inertia about the mass centre, slew torque, duration
C0 = np.array([-0.5, 0.5, 1.0])


def slew(t, y):
    """tau0 = (0, 0, 10 sin(2 pi t / 10)) ft lbf at O_g."""
    return np.zeros(3), np.array([0.0, 0.0, TQ * np.sin(2 * np.pi * t / TF)]), np.zeros((4, 3))


def theta3_rigid(t):
    return TQ * TF / (2 * np.pi * IZZ) * (t - TF / (2 * np.pi) * np.sin(2 * np.pi * t / TF))


def test_no_modes_is_the_rigid_composite_body():
    times = np.arange(101) * 0.1
    out = simulate_free({**REST, "n_modes": 0}, times, slew, h=0.01)
    np.testing.assert_allclose(out["euler123"][:, 2], theta3_rigid(times), atol=1e-10)
    assert abs(np.degrees(out["euler123"][-1, 2]) - 14.2131288) < 1e-7
    assert abs(np.degrees(out["omega"][50, 2]) - 2.8426258) < 1e-7
    assert np.abs(out["euler123"][:, :2]).max() < 1e-12 and np.abs(out["omega"][:, :2]).max() < 1e-12
    # the composite rotates about its (fixed) mass centre, so O_g moves: R = c0 - C(t) c0
    expected_R = np.array([C0 - euler123_to_dcm(th) @ C0 for th in out["euler123"]])
    np.testing.assert_allclose(out["R"], expected_R, atol=1e-10)


# spec AT-9: theta_3 - theta_3,rigid at t = 2.5 s, NT = 2, K scaled by s (EI_x, EI_z and EA)
SPEC_DEVIATION = {1: 0.134933, 10: 0.0137046, 100: 1.38565e-3}


@pytest.fixture(scope="module")
def scaled_runs():
    times = np.arange(11) * 0.25
    runs = {}
    for s, h in ((1, 0.002), (10, 0.002), (100, 0.001)):  # h keeps w_max h <= 0.13
        params = {**REST, "n_modes": 2, "EI_x": 1e4 * s, "EI_z": 4e4 * s, "EA": 1e6 * s}
        runs[s] = simulate_free(params, times, slew, h=h)
    return times, runs


def test_stiffness_to_infinity_converges_to_rigid_motion(scaled_runs):
    times, runs = scaled_runs
    rigid = theta3_rigid(times[-1])
    dev = {s: np.degrees(out["euler123"][-1, 2] - rigid) for s, out in runs.items()}
    for s, ref in SPEC_DEVIATION.items():
        assert abs(dev[s] - ref) <= 1e-4 * ref, (s, dev[s], ref)
    # first-order convergence in 1/s: each decade of stiffness cuts the deviation about 10x
    assert 9.5 < dev[1] / dev[10] < 10.5 and 9.5 < dev[10] / dev[100] < 10.5
    qmax = {s: np.abs(out["q"][-1]).max() for s, out in runs.items()}
    assert 9.0 < qmax[1] / qmax[10] < 11.0 and 9.0 < qmax[10] / qmax[100] < 11.0
    # the base angular rate converges too
    w_rigid = TQ * TF / (2 * np.pi * IZZ) * (1 - np.cos(2 * np.pi * times[-1] / TF))
    errs = [abs(runs[s]["omega"][-1, 2] - w_rigid) for s in (1, 10, 100)]
    assert errs[0] > errs[1] > errs[2] and errs[2] < 1e-3 * w_rigid
