"""Box aerodynamics (eqs. 18-21): closed-form force, zero torque about the box centre, c.m. transfer."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from subsims.aero.model import AeroParams, aero_loads, aero_loads_batch, box_facets, torque_about_cm
from subsims.aero.subsim import Aero
from subsims.satellite import constants as C


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1032)


def random_velocities(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return 7731.0 * v / np.linalg.norm(v, axis=1, keepdims=True) * rng.uniform(0.5, 1.5, size=(n, 1))


def test_force_closed_form(rng: np.random.Generator) -> None:
    """F = -q Cd A_proj v_hat with A_proj = WH|vx| + LH|vy| + LW|vz| (one exposed facet per axis)."""
    p = AeroParams()
    for v in random_velocities(rng, 300):
        force, _ = aero_loads(v.tolist(), p)
        vmag = np.linalg.norm(v)
        vh = v / vmag
        a_proj = 12.0 * abs(vh[0]) + 45.0 * abs(vh[1]) + 60.0 * abs(vh[2])
        expected = -0.5 * C.RHO * vmag**2 * C.CD * a_proj * vh
        np.testing.assert_allclose(force, expected, rtol=1e-13, atol=0)
    # flow along +y: only the right side (45 m^2) is exposed, drag opposes the motion
    force, torque = aero_loads([0.0, 7731.0, 0.0], p)
    assert force == pytest.approx((0.0, -0.5 * C.RHO * 7731.0**2 * C.CD * 45.0, 0.0), rel=1e-15)
    assert torque == (0.0, 0.0, 0.0)


def test_torque_about_box_centre_is_zero(rng: np.random.Generator) -> None:
    """Spec §7.7: for each facet |a_i| |r_cp,i| = LWH/2 and r_cp,i is along the facet normal, so
    T = -q Cd (LWH/2) sum_k v_k e_k x v_hat = -q Cd (LWH/2) v_hat x v_hat = 0 for ANY flow direction
    and ANY box: the listing's torque output about the geometric origin is pure round-off. The torque
    that drives the attitude comes entirely from the c.m. offset (r_cm x F)."""
    for dims in ((15.0, 4.0, 3.0), (2.0, 9.0, 0.5)):
        p = AeroParams(length=dims[0], width=dims[1], height=dims[2])
        for v in random_velocities(rng, 500):
            force, torque = aero_loads(v.tolist(), p)
            scale = np.linalg.norm(force) * max(dims)
            assert np.linalg.norm(torque) <= 1e-15 * scale
    # ...while a single exposed facet alone does produce torque (so the test can see a wrong c.p.)
    facets = box_facets(15.0, 4.0, 3.0)
    _, torque = aero_loads([7000.0, 3000.0, 0.0], AeroParams(), facets=facets[:1])
    assert abs(torque[2]) > 1e-3 * np.linalg.norm(aero_loads([7000.0, 3000.0, 0.0], AeroParams())[0])


def test_torque_transfer_to_cm(rng: np.random.Generator) -> None:
    """physical=True (eq. 21) equals the moment of the facet forces about the c.m.; the listing's sign is opposite."""
    p = AeroParams()
    r_cm = np.array(C.R_CM)
    for v in random_velocities(rng, 50):
        vh = v / np.linalg.norm(v)
        direct = np.zeros(3)
        for area, cp in p.facets:
            aproj = max(float(np.dot(area, vh)), 0.0)
            direct += np.cross(np.array(cp) - r_cm, -0.5 * p.rho * np.dot(v, v) * p.cd * aproj * vh)
        force, torque = aero_loads(v.tolist(), p)
        np.testing.assert_allclose(torque_about_cm(torque, force, C.R_CM, physical=True), direct,
                                   rtol=1e-12, atol=1e-22)
        listing = np.array(torque_about_cm(torque, force, C.R_CM))
        np.testing.assert_allclose(listing, np.array(torque) + np.cross(r_cm, force), rtol=0, atol=0)
        np.testing.assert_allclose(listing, -direct, rtol=1e-12, atol=1e-22)


def test_zero_velocity_and_zero_density() -> None:
    assert aero_loads([0.0, 0.0, 0.0], AeroParams()) == ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    force, torque = aero_loads([1.0, 7000.0, -300.0], AeroParams(rho=0.0))
    assert np.all(np.array(force) == 0.0) and np.all(np.array(torque) == 0.0)


@pytest.mark.parametrize("samples", [5, 65])  # below and above BATCH_FROM: the loop and the NumPy pass
def test_adapter_contract_and_purity(samples: int) -> None:
    sim = Aero()
    assert Aero.algebraic is True
    state = sim.initial_state({})
    assert state.shape == (0,)
    times = np.linspace(0.0, 0.4, samples)
    seen: list[float] = []

    def u(t: float | np.ndarray) -> dict[str, np.ndarray]:  # t (k,) -> (k, 3)
        seen.extend(np.atleast_1d(t).tolist())
        v_body = np.multiply.outer(t, [100.0, 0.0, 0.0]) + [0.0, 7731.0, -50.0]
        return {"R_body": np.array([6.6e6, 0.0, 0.0]), "V_body": v_body}

    out1, end1 = sim.advance(state, times, u)
    out2, _ = sim.advance(state, times, u)
    assert set(out1) == set(Aero.outputs) == {"force", "torque"}
    assert end1.shape == (0,)
    for name in out1:
        assert out1[name].shape == (samples, 3)
        np.testing.assert_array_equal(out1[name], out2[name])
    for j, t in enumerate(times):
        force, torque = aero_loads(u(t)["V_body"].tolist(), sim.p)
        np.testing.assert_array_equal(out1["force"][j], force)
        np.testing.assert_array_equal(out1["torque"][j], torque)
    assert sorted(set(seen)) == times.tolist()
    with pytest.raises(ValueError, match="rho"):
        Aero().initial_state({"rho": -1.0})
    with pytest.raises(ValueError, match="unknown aero parameter"):
        Aero().initial_state({"density": 1.0})


def test_facet_subsets_give_the_moment_of_their_forces(rng: np.random.Generator) -> None:
    """Any set of facets: force = sum of the exposed facets' drags, torque = sum of cp x force (computed here).
    The full box's torque cancels (above), so only a subset shows a wrong component or sign in the torque sum."""
    p = AeroParams(length=7.0, width=2.5, height=1.5)
    facets = box_facets(7.0, 2.5, 1.5)
    largest = np.zeros(3)
    for k, v in enumerate(random_velocities(rng, 60)):
        subset = facets[k % 6:] + facets[:k % 3]
        vh = v / np.linalg.norm(v)
        force, torque = np.zeros(3), np.zeros(3)
        for area, cp in subset:
            aproj = max(float(np.dot(area, vh)), 0.0)
            f = -0.5 * p.rho * np.dot(v, v) * p.cd * aproj * vh
            force, torque = force + f, torque + np.cross(cp, f)
        got_f, got_t = aero_loads(v.tolist(), p, facets=subset)
        np.testing.assert_allclose(got_f, force, rtol=1e-13, atol=1e-30)
        np.testing.assert_allclose(got_t, torque, rtol=0, atol=1e-13 * np.linalg.norm(force) * 7.0)
        largest = np.maximum(largest, np.abs(torque) / max(np.linalg.norm(force), 1e-300))
    assert np.all(largest > 0.1), largest  # every torque component is exercised (moment arms ~1 m)


def test_torque_transfer_of_an_arbitrary_torque_and_force() -> None:
    """torque_about_cm on a torque that is not zero: listing T + r x F, physical (eq. 21) T - r x F."""
    t, f, r = (1.0, -2.0, 3.5), (0.25, 4.0, -1.5), (0.5, -0.75, 2.0)
    rxf = np.cross(r, f)
    np.testing.assert_array_equal(torque_about_cm(t, f, r), np.array(t) + rxf)
    np.testing.assert_array_equal(torque_about_cm(t, f, r, physical=True), np.array(t) - rxf)
    np.testing.assert_array_equal(torque_about_cm(t, f), np.array(t) + np.cross(C.R_CM, f))  # default: the paper's


@pytest.mark.parametrize(("name", "bad", "need"), [("rho", -1e-12, " >= 0"), ("cd", -0.5, " >= 0"),
                                                   ("length", 0.0, " > 0"), ("width", -2.0, " > 0"),
                                                   ("height", 0.0, " > 0"), ("cd", "x", None)])
def test_each_parameter_is_read_and_checked_by_name(name: str, bad, need: str | None) -> None:
    p = AeroParams.from_mapping({name: 7.5})
    assert getattr(p, name) == 7.5 and all(getattr(p, n) == getattr(AeroParams(), n) for n in
                                           ("rho", "cd", "length", "width", "height") if n != name)
    message = f"parameter {name!r} must be " + (f"a finite number{need}" if need else "a number")
    with pytest.raises(ValueError, match="^" + message.replace("(", r"\(") + ", got "):
        AeroParams.from_mapping({name: bad})
    zero_ok = {"rho": 0.0, "cd": 0.0}
    if name in zero_ok:
        assert getattr(AeroParams.from_mapping({name: 0.0}), name) == 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):  # parameters are values: shared, hashed, never changed
        p.rho = 1.0  # type: ignore[misc]
    with pytest.raises(ValueError, match=r"^unknown aero parameter\(s\) \['density'\]; known: rho, cd, length, "
                                         r"width, height$"):
        AeroParams.from_mapping({"density": 1.0})


def test_the_batch_form_equals_the_scalar_form_bit_for_bit(rng: np.random.Generator) -> None:
    """aero_loads_batch (what the subsim runs, 65 samples a call) against aero_loads (the listing's form, which
    RK-U runs): every row identical, facet subsets, the zero vector (vecnorm's guard) and NaN included."""
    pool = random_velocities(rng, 20_000)
    speed = [float(np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])) for v in pool.tolist()]
    squared_differ = [i for i, s in enumerate(speed) if s**2 != s * s]  # C pow(s, 2) is not always s * s
    assert len(squared_differ) >= 3
    velocities = np.vstack([pool[:200], pool[squared_differ], np.zeros((1, 3)), [[np.nan, 7000.0, 0.0]],
                            [[0.0, -7731.0, 0.0]], [[1e-300, 0.0, 0.0]]])
    p = AeroParams(length=7.0, width=2.5, height=1.5)
    facets = box_facets(7.0, 2.5, 1.5)
    for subset in (facets, facets[:1], facets[2:5], facets[3:] + facets[:2]):
        force, torque = aero_loads_batch(velocities, p, subset)
        assert force.shape == torque.shape == velocities.shape
        for v, f, t in zip(velocities, force, torque):
            want_f, want_t = aero_loads(v.tolist(), p, facets=subset)
            np.testing.assert_array_equal(f, want_f)
            np.testing.assert_array_equal(t, want_t)
    assert np.isnan(force[-3]).all() and not np.isnan(force[:-3]).any()
