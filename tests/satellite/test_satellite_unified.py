"""Coupling transforms, the RK-U unified reference, the cases, and a small RF-D loop of the three adapters."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from subsims.aero.subsim import Aero
from subsims.attitude.model import EulerSingularityError, dcm321
from subsims.attitude.subsim import Attitude
from subsims.orbit.subsim import Orbit
from subsims.satellite.cases import CASES
from subsims.satellite.transforms import (
    altitude_km,
    body_to_inertial,
    inertial_to_body,
    limit_angles,
    torque_to_cm,
)
from subsims.satellite.unified import run_unified

NO_AIR = {"rho": 0.0}


def linear_inputs(times: np.ndarray, **signals: np.ndarray) -> Callable[[float], dict[str, np.ndarray]]:
    """u(t) interpolating (n, 3) samples linearly, like the listings' interp."""

    def u(t: float | np.ndarray) -> dict[str, np.ndarray]:  # t (k,) -> (k, 3)
        return {name: np.stack([np.interp(t, times, v[:, k]) for k in range(v.shape[1])], axis=-1)
                for name, v in signals.items()}

    return u


# --- transforms -------------------------------------------------------------------------------------------


def test_frame_transforms() -> None:
    rng = np.random.default_rng(7)
    phi = rng.uniform(-1.5, 1.5, size=(20, 3))
    vec = rng.normal(size=(20, 3)) * 1e6
    body = inertial_to_body(vec, phi)
    assert body.shape == (20, 3)
    for k in range(20):
        np.testing.assert_allclose(body[k], np.array(dcm321(phi[k])) @ vec[k], rtol=1e-15, atol=1e-9)
    np.testing.assert_allclose(body_to_inertial(body, phi), vec, rtol=0, atol=1e-8)
    np.testing.assert_allclose(np.linalg.norm(body, axis=1), np.linalg.norm(vec, axis=1), rtol=1e-15)
    with pytest.raises(ValueError, match="samples"):
        inertial_to_body(vec, phi[:5])
    with pytest.raises(ValueError, match="shape"):
        body_to_inertial(np.zeros((3, 2)), np.zeros((3, 3)))


def test_output_limiting_and_altitude() -> None:
    rng = np.random.default_rng(8)
    phi = rng.uniform(-40.0, 40.0, size=(100, 3))  # unlimited angles of a tumble...
    phi[:, 1] = rng.uniform(-1.5, 1.5, size=100)  # ...with phi_y inside (-90, 90) deg as the kinematics keeps it
    lim = limit_angles(phi)
    assert np.all(np.abs(lim[:, [0, 2]]) <= math.pi) and np.all(np.abs(lim[:, 1]) <= math.pi / 2)
    np.testing.assert_allclose(lim[:, 1], phi[:, 1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.cos(lim - phi), 1.0, rtol=0, atol=1e-12)  # same angles mod 2 pi
    for k in range(100):
        np.testing.assert_allclose(dcm321(lim[k]), dcm321(phi[k]), rtol=0, atol=1e-14)
    np.testing.assert_allclose(altitude_km(np.array([[6667650.0, 0.0, 0.0]])), [[300.0]], rtol=1e-12)


def test_torque_to_cm_signs() -> None:
    force = np.array([[0.0, -0.06, 0.0], [0.01, 0.0, -0.02]])
    torque = np.array([[1e-18, 0.0, 0.0], [0.0, 0.0, 0.0]])
    listing = torque_to_cm(torque, force, r_cm=[1.0, 0.1, 0.1])
    physical = torque_to_cm(torque, force, r_cm=[1.0, 0.1, 0.1], physical=True)
    rxf = np.cross([1.0, 0.1, 0.1], force)
    np.testing.assert_array_equal(listing, torque + rxf)
    np.testing.assert_array_equal(physical, torque - rxf)
    # drag of 0.06 N along -y acting at the geometric origin, which lies 1 m behind the c.m. (along -x):
    # moment about the c.m. = (-x) x (-0.06 y) = +0.06 z; the listing's sign gives -0.06 z
    assert physical[0, 2] == pytest.approx(0.06, rel=1e-15)
    assert listing[0, 2] == pytest.approx(-0.06, rel=1e-15)


# --- RK-U ---------------------------------------------------------------------------------------------------


def test_unified_without_air_matches_stand_alone_models() -> None:
    c = CASES["case1"]
    out = run_unified(c["orbit"], c["attitude"], NO_AIR, 300.0, 0.1)
    t = out["t"]
    assert t.shape == (3001,) and t[-1] == pytest.approx(300.0)
    orbit = Orbit()
    xo = orbit.initial_state(c["orbit"])
    ref, _ = orbit.advance(xo, t, lambda s: {"f_aero": np.zeros(3)})
    for name in ("R", "V"):
        np.testing.assert_allclose(out["orbit"][name], ref[name], rtol=1e-14, atol=0)
    # attitude fed the orbit's samples, linearly interpolated: differs only by that interpolation of R
    att = Attitude()
    xa = att.initial_state(c["attitude"])
    ref_a, _ = att.advance(xa, t, linear_inputs(t, R=ref["R"], torque=np.zeros_like(ref["R"])))
    assert np.max(np.abs(out["attitude"]["phi"])) > 1e-6  # gravity gradient really acts
    # the chord of R between 0.1 s samples is off the arc by ~R (n h)^2 / 8 = 0.011 m, ~2e-9 of R: so
    # the gravity-gradient torque, and the attitude response, agree to a few 1e-9 relative
    for port in ("phi", "omega", "omega_dot"):
        x, y = out["attitude"][port], ref_a[port]
        assert np.max(np.abs(x - y)) <= 1e-8 * np.max(np.abs(x)), port
    assert np.all(out["aero"]["force"] == 0.0)


def test_unified_short_runs_finite() -> None:
    for name in ("case1", "case3"):
        c = CASES[name]
        out = run_unified(c["orbit"], c["attitude"], c["aero"], 200.0, 0.1, r_cm=c["transfer"]["r_cm"])
        arrays = [out["t"], *out["orbit"].values(), *out["attitude"].values(), *out["aero"].values()]
        assert all(np.all(np.isfinite(a)) for a in arrays)
        for group in ("orbit", "attitude", "aero"):
            for a in out[group].values():
                assert a.shape == (2001, 3)
        f = out["aero"]["force"]
        assert 0.05 < np.min(np.linalg.norm(f, axis=1)) < np.max(np.linalg.norm(f, axis=1)) < 0.1  # N, spec §7.7
        assert np.max(np.abs(out["aero"]["torque"])) < 1e-15  # about the box centre: zero (spec §7.7)
        # drag slows the orbit: specific energy decreases
        r, v = out["orbit"]["R"], out["orbit"]["V"]
        e = 0.5 * np.sum(v * v, axis=1) - 3.985140974547934e14 / np.linalg.norm(r, axis=1)
        assert e[-1] < e[0]
    with pytest.raises(ValueError, match="unknown aero"):
        run_unified({}, {}, {"cdd": 1.0}, 1.0, 0.1)


def test_unified_singularity_is_a_model_error() -> None:
    att = {"phi0": [0.0, math.radians(89.0), 0.0], "omega0": [0.0, 0.02, 0.0],
           **{g: 0.0 for g in ("a0", "a1", "b0", "b1", "c0", "c1")}}
    with pytest.raises(EulerSingularityError, match="at t = "):  # a PhysicsError: no cosim in the physics
        run_unified({}, att, {}, 10.0, 0.1)


def test_cases_match_spec() -> None:
    assert set(CASES) == {"case1", "case2", "case3"}
    z = {n: (CASES[n]["attitude"]["c0"], CASES[n]["attitude"]["c1"]) for n in CASES}
    assert z == {"case1": (1000.0, 100.0), "case2": (0.0, 0.0), "case3": (0.0, 0.0)}
    assert CASES["case2"]["attitude"]["a0"] == 1000.0 and CASES["case3"]["attitude"]["b1"] == 0.0
    for c in CASES.values():
        Orbit().initial_state(c["orbit"])
        Attitude().initial_state(c["attitude"])
        Aero().initial_state(c["aero"])
    CASES["case1"]["attitude"]["inertia"][0] = -1.0  # the cases do not share mutable parts
    try:
        assert CASES["case2"]["attitude"]["inertia"][0] == 11250.0
    finally:
        CASES["case1"]["attitude"]["inertia"][0] = 11250.0


# --- a small RF-D run of the adapters and transforms (spec §5) ------------------------------------------


def rfd_run(case: dict, t_stop: float, ndp: int = 5, dtmaj: float = 0.4, tol: float = 1e-14,
            res: float = 1e-14) -> tuple[dict[str, np.ndarray], list[int]]:
    """orbit -> attitude -> aero in sequence; aero force/torque fed back across the recursive transfer point."""
    orbit, att, aero = Orbit(), Attitude(), Aero()
    xo, xa = orbit.initial_state(case["orbit"]), att.initial_state(case["attitude"])
    aero.initial_state(case["aero"])
    r_cm = case["transfer"]["r_cm"]
    stages = []
    for i in range(round(t_stop / dtmaj)):
        times = i * dtmaj + np.linspace(0.0, dtmaj, ndp)
        fb = np.zeros((ndp, 6))  # stage 0: zero feedback
        for stage in range(100):
            o, xo_end = orbit.advance(xo, times, linear_inputs(times, f_aero=fb[:, :3]))
            a, xa_end = att.advance(xa, times, linear_inputs(times, R=o["R"], torque=fb[:, 3:]))
            r_b, v_b = inertial_to_body(o["R"], a["phi"]), inertial_to_body(o["V"], a["phi"])
            f, _ = aero.advance(np.empty(0), times, linear_inputs(times, R_body=r_b, V_body=v_b))
            new = np.hstack([body_to_inertial(f["force"], a["phi"]), torque_to_cm(f["torque"], f["force"], r_cm)])
            diff = np.max(np.abs(new - fb), axis=0)
            span = np.ptp(new, axis=0)
            converged = stage > 0 and bool(np.all((diff <= tol * span) | (diff <= res)))
            fb = new
            if converged:
                break
        else:
            raise AssertionError("RF-D did not converge")
        stages.append(stage)
        xo, xa = xo_end, xa_end
    return {"R": xo[:3], "V": xo[3:], "phi": xa[:3], "omega": xa[3:]}, stages


@pytest.mark.parametrize("name", ["case1", "case3"])
def test_rfd_loop_agrees_with_unified(name: str) -> None:
    """Spec §14 item 9: RF and RK-U agree closely early in the run (they differ only by the linear
    interpolation of aero loads and radius between 0.1 s samples inside the RK stages)."""
    case = CASES[name]
    end, stages = rfd_run(case, 40.0)
    assert max(stages) <= 3 and np.median(stages) == 2  # stages 0, 1, 2: "typically three" (spec §10)
    ref = run_unified(case["orbit"], case["attitude"], case["aero"], 40.0, 0.1, r_cm=case["transfer"]["r_cm"])
    np.testing.assert_allclose(end["R"], ref["orbit"]["R"][-1], rtol=0, atol=1e-8)  # measured 7e-10 m
    np.testing.assert_allclose(end["V"], ref["orbit"]["V"][-1], rtol=0, atol=1e-11)  # 7e-13 m/s
    np.testing.assert_allclose(end["phi"], ref["attitude"]["phi"][-1], rtol=0, atol=1e-11)  # 4e-12 rad
    np.testing.assert_allclose(end["omega"], ref["attitude"]["omega"][-1], rtol=0, atol=1e-12)  # 2e-13 rad/s
    # and the aero force matters at that level: without it the attitude differs by far more
    no_air = run_unified(case["orbit"], case["attitude"], NO_AIR, 40.0, 0.1)
    assert np.max(np.abs(no_air["attitude"]["phi"][-1] - end["phi"])) > 1e-8
