"""Coupling.evaluate: the target's samples, or a ValueError naming the coupling for a transform that fails,
gives the wrong shape, or produces NaN or inf (wherever it is, however large the finite values are)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from cosim.coupler.couplings import Coupling, check_couplings


def _outputs(y: object) -> dict:
    return {"a": {"y": y, "w": np.ones((5, 2))}}


def test_identity_passes_the_array_through() -> None:
    y = np.arange(15.0).reshape(5, 3)
    assert Coupling.make("b.u", "a.y").evaluate(_outputs(y), 3, 5) is y


@pytest.mark.parametrize("y", [[[1, 2, 3]] * 5, np.ones((5, 3), dtype=np.float32), np.ones((5, 3), dtype=">f8")])
def test_other_values_become_float64(y: object) -> None:
    value = Coupling.make("b.u", "a.y").evaluate(_outputs(y), 3, 5)
    assert type(value) is np.ndarray and value.dtype == np.float64 and value.dtype.isnative
    np.testing.assert_array_equal(value, np.asarray(y, dtype=np.float64))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("where", [0, 7, 14])
def test_nan_or_inf_is_refused_naming_the_coupling(bad: float, where: int) -> None:
    y = np.ones((5, 3))
    y.flat[where] = bad
    with pytest.raises(ValueError, match=r"^coupling a\.y -> b\.u: transform 'identity' produced NaN or inf \(as a "):
        Coupling.make("b.u", "a.y").evaluate(_outputs(y), 3, 5)


def test_the_check_agrees_with_isfinite_all() -> None:
    rng = np.random.default_rng(3)
    c = Coupling.make("b.u", "a.y")
    for _ in range(300):
        n, size = int(rng.integers(1, 70)), int(rng.integers(0, 4))
        y = rng.choice([0.0, -0.0, 1.0, 1e308, -1.7976931348623157e308, 5e-324, np.nan, np.inf, -np.inf],
                       size=(n, size), p=[0.2, 0.1, 0.2, 0.2, 0.2, 0.09, 0.003, 0.004, 0.003])
        if np.isfinite(y).all():
            assert c.evaluate(_outputs(y), size, n) is y
        else:
            with pytest.raises(ValueError, match="produced NaN or inf"):
                c.evaluate(_outputs(y), size, n)


def test_large_finite_values_pass_without_warnings() -> None:
    y = np.full((5, 3), 1.7976931348623157e308)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert Coupling.make("b.u", "a.y").evaluate(_outputs(y), 3, 5) is y


def test_wrong_shape_is_refused_naming_the_coupling() -> None:
    with pytest.raises(ValueError, match=r"^coupling a\.w -> b\.u: transform 'identity' gave shape \(5, 2\), "
                                         r"need \(5, 3\)$"):
        Coupling.make("b.u", "a.w").evaluate(_outputs(np.ones((5, 3))), 3, 5)
    with pytest.raises(ValueError, match=r"gave shape \(4, 3\), need \(5, 3\)"):
        Coupling.make("b.u", "a.y").evaluate(_outputs(np.ones((4, 3))), 3, 5)


def test_failing_transform_is_reported_naming_the_coupling() -> None:
    c = Coupling.make("b.u", ["a.y", "a.w"], "subsims.satellite.transforms:torque_to_cm")
    message = r"^coupling a\.y, a\.w -> b\.u: transform 'subsims\.satellite\.transforms:torque_to_cm' failed: force"
    with pytest.raises(ValueError, match=message):
        c.evaluate(_outputs(np.ones((5, 3))), 3, 5)
    with pytest.raises(ValueError, match="failed: could not convert"):
        Coupling.make("b.u", "a.y").evaluate(_outputs([["x"] * 3] * 5), 3, 5)


def test_a_transform_may_give_one_wide_samples_flat_as_a_model_may() -> None:
    """A model's (n,) output for a 1-wide port is taken; a transform's was refused, "(2,) ... takes (2, 1)" (a
    newcomer probe). Wider targets still need (n, width)."""
    flat = Coupling.make("b.u", "a.y", "subsims.satellite.transforms:torque_to_cm")
    flat = Coupling(flat.target, flat.sources, lambda y: y[:, 0] * 2.0, {}, "halving")
    check_couplings([flat], {"b": {"u": 1}}, {"a": {"y": 3}})  # its trial before the run refused it first
    got = flat.evaluate(_outputs(np.arange(15.0).reshape(5, 3)), 1, 5)
    assert got.shape == (5, 1) and got[:, 0].tolist() == [0.0, 6.0, 12.0, 18.0, 24.0]
    with pytest.raises(ValueError, match=r"into shape \(2,\); input b.u takes 3 per sample"):
        check_couplings([flat], {"b": {"u": 3}}, {"a": {"y": 3}})
    with pytest.raises(ValueError, match=r"gave shape \(5,\), need \(5, 3\)"):
        flat.evaluate(_outputs(np.ones((5, 3))), 3, 5)


def test_a_failing_transform_says_what_it_raised_and_where() -> None:
    def boom(y: np.ndarray) -> np.ndarray:
        raise ValueError("bad gain")

    c = Coupling.make("b.u", "a.y")
    c = Coupling(c.target, c.sources, boom, {}, "xf:boom")
    with pytest.raises(ValueError, match=r"transform 'xf:boom' failed: bad gain \(ValueError at "
                                         r"test_couplings_evaluate\.py:\d+\)$"):
        c.evaluate(_outputs(np.ones((5, 3))), 3, 5)


def test_a_transform_failing_inside_numpy_is_located_in_its_own_code() -> None:
    """``np.reshape(x, (7, 3))`` in a transform was located at fromnumeric.py:54 (a red team)."""
    def reshaping(y: np.ndarray) -> np.ndarray:
        return np.reshape(y, (7, 3))

    c = Coupling.make("b.u", "a.y")
    c = Coupling(c.target, c.sources, reshaping, {}, "xf:reshaping")
    with pytest.raises(ValueError, match=r"\(ValueError at test_couplings_evaluate\.py:\d+\)$"):
        c.evaluate(_outputs(np.ones((5, 3))), 3, 5)


def test_a_transform_making_nan_from_finite_sources_is_told_its_own_arithmetic() -> None:
    """A user transform dividing by zero was told 'as a coupling iteration that diverges makes them: a shorter
    [coupling] interval then' (a newcomer probe): its sources were finite and small, the transform is to look at."""
    from cosim.coupler.couplings import SignalRef

    def boom(y: np.ndarray, k: float) -> np.ndarray:
        with np.errstate(over="ignore"):
            return y * k

    def coupling(k: float) -> Coupling:
        return Coupling(SignalRef.parse("b.u"), (SignalRef.parse("a.y"),), boom, {"k": k}, "mine:boom")

    c = coupling(np.inf)
    with pytest.raises(ValueError) as err:
        c.evaluate(_outputs(np.full((5, 3), 2.5)), 3, 5)
    assert str(err.value).endswith("produced NaN or inf from finite sources of at most 2.5 in size: its own "
                                   "arithmetic (a division by zero?)"), err.value
    with pytest.raises(ValueError, match=r"diverges makes them: a shorter \[coupling\] interval then; its sources "
                                         r"reached 1e\+300\)$"):
        coupling(1e10).evaluate(_outputs(np.full((5, 3), 1e300)), 3, 5)
