"""The satellite's coupling transforms, vectorised, give the bits of the model formulas they were computed
with (``aero.model.torque_about_cm`` by columns, ``numerics.dcm321_batch``), on random and edge inputs; and
inputs of the wrong shape are still refused."""

from __future__ import annotations

import numpy as np
import pytest

from subsims.aero.model import torque_about_cm
from subsims.numerics import DCM_ARRAYS_FROM, dcm321_batch, rotation321
from subsims.satellite.transforms import body_to_inertial, inertial_to_body, torque_to_cm

EDGES = np.array([0.0, -0.0, 1.0, -1.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1e-300, 1e300, -1e300,
                  1.7976931348623157e308, np.inf, -np.inf, np.nan, 0.1, 1e-18, -3.5])


def _inputs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-20, 20, size=(n, 3)), rng.normal(size=(n, 3))
    a.flat[: n], b.flat[-n:] = rng.choice(EDGES, n), rng.choice(EDGES, n)  # edge values among ordinary ones
    return a, b


def _same_bits(x: np.ndarray, y: np.ndarray) -> None:
    """Equal bit for bit, NaN aside: NaN where the other has NaN, of any sign (which of two NaN operands an
    operation passes on, and so the sign, depends on NumPy's loop for the memory layout, not on the formula)."""
    assert x.shape == y.shape and x.dtype == y.dtype == np.float64
    nan = np.isnan(x)
    np.testing.assert_array_equal(nan, np.isnan(y))
    assert np.where(nan, 0.0, x).tobytes() == np.where(nan, 0.0, y).tobytes()


def _torque_reference(t: np.ndarray, f: np.ndarray, r_cm: list[float], physical: bool) -> np.ndarray:
    """The formula column by column, as torque_to_cm computed it before it was vectorised."""
    return np.column_stack(torque_about_cm(t.T, f.T, np.asarray(r_cm, dtype=np.float64), physical))


@pytest.mark.parametrize("n", [1, 5, 65, 200])
@pytest.mark.parametrize("physical", [False, True])
@pytest.mark.parametrize("r_cm", [[1.0, 0.1, 0.1], [-0.0, 3e-310, -7.25], [np.inf, 0.0, 1.0]])
def test_torque_to_cm_bits(n: int, physical: bool, r_cm: list[float]) -> None:
    for seed in range(5):
        t, f = _inputs(n, seed)
        with np.errstate(invalid="ignore", over="ignore"):
            expected = _torque_reference(t, f, r_cm, physical)
            _same_bits(torque_to_cm(t, f, r_cm=r_cm, physical=physical), expected)
            # the checked path (not float64 (n, 3) arrays already): lists, float32, a transposed copy, 1-D
            _same_bits(torque_to_cm(t.tolist(), f.tolist(), r_cm, physical), expected)
            _same_bits(torque_to_cm(np.asfortranarray(t), f[::1], tuple(r_cm), physical), expected)
            t32 = t.astype(np.float32)
            _same_bits(torque_to_cm(t32, f, r_cm, physical), _torque_reference(t32.astype(np.float64), f, r_cm,
                                                                                physical))
            _same_bits(torque_to_cm(t[0], f[0], r_cm, physical), expected[:1])


@pytest.mark.parametrize(("torque", "force", "match"), [
    (np.zeros((5, 3)), np.zeros((4, 3)), "torque has 5 samples but force has 4"),
    (np.zeros((5, 2)), np.zeros((5, 2)), r"torque must have shape \(n, 3\), got \(5, 2\)"),
    (np.zeros((5, 3)), np.zeros((5, 3, 1)), r"force must have shape \(n, 3\), got \(5, 3, 1\)"),
    (np.zeros(4), np.zeros(4), r"torque must have shape \(n, 3\), got \(4,\)"),
    (np.zeros((0, 3)), np.zeros((1, 3)), "torque has 0 samples but force has 1"),
])
def test_torque_to_cm_refuses_bad_shapes(torque: np.ndarray, force: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        torque_to_cm(torque, force)


@pytest.mark.parametrize("r_cm", [[1.0, 0.1], [[1.0, 0.1, 0.1]], 1.0])
def test_torque_to_cm_refuses_bad_r_cm(r_cm: object) -> None:
    with pytest.raises(ValueError, match="parameter 'r_cm' must be 3 numbers"):
        torque_to_cm(np.zeros((5, 3)), np.zeros((5, 3)), r_cm=r_cm)  # type: ignore[arg-type]


def _frame_reference(v: np.ndarray, phi: np.ndarray, to_body: bool) -> np.ndarray:
    """The rotations as the formula: A(phi) v or A(phi)^T v by einsum on dcm321_batch."""
    return np.einsum("nij,nj->ni" if to_body else "nji,nj->ni", dcm321_batch(phi), v)


@pytest.mark.parametrize("n", [1, 5, 65])
def test_frame_transforms_bits(n: int) -> None:
    for seed in range(5):
        v, phi = _inputs(n, seed)
        with np.errstate(invalid="ignore", over="ignore"):
            for to_body, transform in ((True, inertial_to_body), (False, body_to_inertial)):
                expected = _frame_reference(v, phi, to_body)
                _same_bits(transform(v, phi), expected)
                _same_bits(transform(v, phi.copy()), expected)  # the remembered DCM
                _same_bits(transform(v.tolist(), phi.tolist()), expected)
                _same_bits(transform(v[0], phi[0]), expected[:1])


@pytest.mark.parametrize("n", [0, 1, 5, DCM_ARRAYS_FROM - 1, DCM_ARRAYS_FROM, 65])
def test_dcm321_batch_bits(n: int) -> None:
    """Both forms of dcm321_batch (rows' floats below DCM_ARRAYS_FROM rows, columns from it) give the bits of the
    formula on each row's NumPy sines and cosines, and of the columns form on the same rows."""
    for seed in range(5):
        phi, _ = _inputs(max(n, 1), seed)
        phi = phi[:n]
        with np.errstate(invalid="ignore", over="ignore"):
            got = dcm321_batch(phi)
            assert got.shape == (n, 3, 3)
            rows = [np.array(rotation321(s, c)) for s, c in zip(np.sin(phi).tolist(), np.cos(phi).tolist())]
            _same_bits(got.reshape(-1, 9), np.array(rows).reshape(-1, 9))
            padded = np.vstack([phi, np.zeros((DCM_ARRAYS_FROM, 3))])  # the same rows, by columns
            _same_bits(got.reshape(-1, 9), dcm321_batch(padded)[:n].reshape(-1, 9))
