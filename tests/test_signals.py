"""Signal segments (cosim.signals): validation messages, polynomial exactness, exact samples.

Each interpolation scheme reproduces polynomials up to a known degree (``SCHEMES``): linear 1,
cubic 3, lagrange n-1 for n samples. The tests check that degree exactly (1e-12 relative, at
arbitrary times inside the segment, uniform and non-uniform grids, several channels) and check
that one degree more is *not* reproduced, so a scheme that silently degrades fails here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cosim import signals
from cosim.signals import SCHEMES, Segment, SegmentError, check_time_grid, interpolant

props = settings(
    max_examples=200, derandomize=True, database=None, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
RTOL = 1e-12

# --- validation -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("times", "values", "match"),
    [
        ([0.0, 1.0, 2.0], [[1.0], [2.0]], r"values must have shape \(3, m\) to match 3 times, got \(2, 1\)"),
        ([0.0, 1.0], [[[1.0]], [[2.0]]], r"values must have shape \(2, m\).*got \(2, 1, 1\)"),
        ([0.0, 1.0], [], r"values must have shape \(2, m\).*got \(0, 1\)"),
        ([0.0, 1.0, 2.0], [[0.0, 1.0], [np.nan, 1.0], [0.0, 1.0]], r"values\[1, 0\] is nan: samples must be finite"),
        ([0.0, 1.0], [[0.0, np.inf], [0.0, 0.0]], r"values\[0, 1\] is inf: samples must be finite"),
        ([0.0, 1.0], [[0.0], [-np.inf]], r"values\[1, 0\] is -inf: samples must be finite"),
        ([0.0, np.nan, 2.0], [[0.0], [1.0], [2.0]], r"times contains NaN or inf at index 1"),
        ([0.0, 1.0, np.inf], [[0.0], [1.0], [2.0]], r"times contains NaN or inf at index 2"),
        ([0.0, 2.0, 1.0], [[0.0], [1.0], [2.0]], r"strictly increasing: t\[1\]=2\.0 >= t\[2\]=1\.0"),
        ([0.0, 1.0, 1.0, 2.0], [[0.0], [1.0], [1.0], [2.0]], r"strictly increasing: t\[1\]=1\.0 >= t\[2\]=1\.0"),
        ([], [], r"times must be a non-empty 1-D array, got shape \(0,\)"),
        ([[0.0, 1.0]], [[0.0], [1.0]], r"times must be a non-empty 1-D array, got shape \(1, 2\)"),
    ],
    ids=[
        "too-few-rows",
        "3-d-values",
        "empty-values",
        "nan-value",
        "inf-value",
        "minus-inf-value",
        "nan-time",
        "inf-time",
        "non-monotonic",
        "duplicate-time",
        "empty",
        "2-d-times",
    ],
)
def test_invalid_segments_say_what_is_wrong(times, values, match) -> None:
    with pytest.raises(SegmentError, match=match):
        Segment(times, values)


def test_names_and_units_must_match_the_channels() -> None:
    with pytest.raises(SegmentError, match=r"2 channels need 2 names and units, got 1 and 2"):
        Segment([0.0, 1.0], [[0.0, 1.0], [1.0, 2.0]], names=["x"], units=["m", "m"])
    seg = Segment([0.0, 1.0], [[0.0, 1.0], [1.0, 2.0]])
    assert seg.names == ("y[0]", "y[1]") and seg.units == ("", "")


def test_unknown_scheme_names_the_known_ones() -> None:
    with pytest.raises(SegmentError, match=r"unknown interpolation scheme 'spline'; known: linear, cubic, lagrange"):
        Segment([0.0, 1.0], [0.0, 1.0]).interpolant("spline")


def test_segment_error_is_a_value_error_and_the_segment_is_read_only() -> None:
    assert issubclass(SegmentError, ValueError)
    seg = Segment([0.0, 1.0], [0.0, 1.0])
    assert seg.values.shape == (2, 1)  # 1-D values are one channel
    with pytest.raises(ValueError):
        seg.values[0, 0] = 5.0
    with pytest.raises(ValueError):
        seg.times[0] = 5.0


@props
@given(
    st.lists(st.floats(-1e6, 1e6), min_size=2, max_size=10, unique=True).map(sorted),
    st.data(),
)
def test_first_non_increasing_step_is_reported(grid: list[float], data: st.DataObject) -> None:
    i = data.draw(st.integers(0, len(grid) - 2))
    bad = list(grid)
    bad[i + 1] = data.draw(st.sampled_from([bad[i], bad[i] - 1.0, -1e7]))  # duplicate, or going back
    if i + 2 < len(bad):
        bad[i + 2 :] = [x + 2e7 for x in bad[i + 2 :]]  # everything after the fault increases again
    with pytest.raises(SegmentError, match=rf"strictly increasing: t\[{i}\]=.* >= t\[{i + 1}\]="):
        check_time_grid(np.array(bad))


# --- grids and polynomials -------------------------------------------------------------------------


@st.composite
def grids(draw: st.DrawFn, n: int, uniform: bool) -> np.ndarray:
    """n strictly increasing times; non-uniform steps differ by up to a factor of 5."""
    t0 = draw(st.one_of(st.just(0.0), st.floats(-1e3, 1e3)))
    span = draw(st.floats(1e-3, 1e3))
    if uniform:
        t = np.linspace(t0, t0 + span, n)
    else:
        steps = np.array(draw(st.lists(st.floats(0.2, 1.0), min_size=n - 1, max_size=n - 1)))
        t = t0 + span * np.concatenate([[0.0], np.cumsum(steps) / steps.sum()])
    assert np.all(np.diff(t) > 0)
    return t


def polynomial(coeffs: np.ndarray, t: np.ndarray | float, centre: float, scale: float) -> np.ndarray:
    """Channels sum_k c[k, j] s**k with s = (t - centre) / scale (a polynomial in t of degree len(c) - 1)."""
    s = (np.asarray(t, dtype=float) - centre) / scale
    return np.stack([np.polynomial.polynomial.polyval(s, coeffs[:, j]) for j in range(coeffs.shape[1])], axis=-1)


def coefficients(degree: int, channels: int) -> st.SearchStrategy:
    """Random coefficients whose top-degree term is not negligible (|c_d| >= 0.1)."""
    lower = st.lists(st.floats(-1.0, 1.0), min_size=degree * channels, max_size=degree * channels)
    top = st.lists(
        st.floats(0.1, 1.0).flatmap(lambda x: st.sampled_from([x, -x])), min_size=channels, max_size=channels
    )
    return st.tuples(lower, top).map(lambda lt: np.array(lt[0] + lt[1]).reshape(degree + 1, channels))


def eval_points(t: np.ndarray, fracs: list[float]) -> np.ndarray:
    """Arbitrary times inside [t[0], t[-1]] (clipped: t0 + f (tn - t0) can round past tn)."""
    return np.clip(t[0] + np.array(fracs) * (t[-1] - t[0]), t[0], t[-1])


def max_error(scheme: str, t: np.ndarray, coeffs: np.ndarray, at: np.ndarray) -> float:
    """Largest error of ``scheme`` on the sampled polynomial, relative to the polynomial's size."""
    centre, scale = 0.5 * (t[0] + t[-1]), t[-1] - t[0]
    f = Segment(t, polynomial(coeffs, t, centre, scale)).interpolant(scheme)
    got = np.array([f(x) for x in at])
    want = polynomial(coeffs, at, centre, scale)
    size = np.abs(coeffs).sum()  # bounds |p| on the segment, where |s| <= 1/2
    return float(np.max(np.abs(got - want)) / size)


FRACS = st.lists(st.floats(0.0, 1.0), min_size=1, max_size=12)
CHANNELS = st.integers(1, 4)
UNIFORM = st.booleans()


@props
@given(st.integers(2, 12), UNIFORM, CHANNELS, st.data())
def test_linear_reproduces_degree_1(n: int, uniform: bool, m: int, data: st.DataObject) -> None:
    t = data.draw(grids(n, uniform))
    err = max_error("linear", t, data.draw(coefficients(1, m)), eval_points(t, data.draw(FRACS)))
    assert err <= RTOL


@props
@given(st.integers(4, 12), UNIFORM, CHANNELS, st.data())
def test_cubic_reproduces_degree_3(n: int, uniform: bool, m: int, data: st.DataObject) -> None:
    t = data.draw(grids(n, uniform))
    err = max_error("cubic", t, data.draw(coefficients(3, m)), eval_points(t, data.draw(FRACS)))
    assert err <= RTOL


@props
@given(st.integers(2, 3), UNIFORM, CHANNELS, st.data())
def test_cubic_on_fewer_than_four_samples_is_the_full_polynomial(
    n: int, uniform: bool, m: int, data: st.DataObject
) -> None:
    t = data.draw(grids(n, uniform))
    at = eval_points(t, data.draw(FRACS))
    assert max_error("cubic", t, data.draw(coefficients(n - 1, m)), at) <= RTOL
    values = np.array(data.draw(st.lists(st.floats(-1e3, 1e3), min_size=n * m, max_size=n * m))).reshape(n, m)
    seg = Segment(t, values)
    for x in at:
        np.testing.assert_array_equal(seg(x, "cubic"), seg(x, "lagrange"))


@pytest.mark.parametrize("scheme", list(SCHEMES))
def test_one_sample_is_a_constant(scheme: str) -> None:
    seg = Segment([2.0], [[1.5, -3.0]])
    for x in (2.0, 1.0, 3.0):
        np.testing.assert_array_equal(seg(x, scheme), [1.5, -3.0])


@props
@given(st.integers(2, 8), UNIFORM, CHANNELS, st.data())
def test_lagrange_reproduces_degree_n_minus_1(n: int, uniform: bool, m: int, data: st.DataObject) -> None:
    t = data.draw(grids(n, uniform))
    err = max_error("lagrange", t, data.draw(coefficients(n - 1, m)), eval_points(t, data.draw(FRACS)))
    assert err <= RTOL


def midpoints(t: np.ndarray) -> np.ndarray:
    return 0.5 * (t[:-1] + t[1:])


# one degree more than a scheme reproduces must leave an error far above the exactness tolerance
NOT_EXACT = 1e3 * RTOL


@props
@given(st.integers(2, 12), UNIFORM, CHANNELS, st.data())
def test_linear_does_not_reproduce_degree_2(n: int, uniform: bool, m: int, data: st.DataObject) -> None:
    t = data.draw(grids(n, uniform))
    assert max_error("linear", t, data.draw(coefficients(2, m)), midpoints(t)) > NOT_EXACT


@props
@given(st.integers(5, 12), UNIFORM, CHANNELS, st.data())
def test_cubic_does_not_reproduce_degree_4(n: int, uniform: bool, m: int, data: st.DataObject) -> None:
    t = data.draw(grids(n, uniform))
    assert max_error("cubic", t, data.draw(coefficients(4, m)), midpoints(t)) > NOT_EXACT


@props
@given(st.integers(2, 8), UNIFORM, CHANNELS, st.data())
def test_lagrange_does_not_reproduce_degree_n(n: int, uniform: bool, m: int, data: st.DataObject) -> None:
    t = data.draw(grids(n, uniform))
    assert max_error("lagrange", t, data.draw(coefficients(n, m)), midpoints(t)) > NOT_EXACT


@pytest.mark.parametrize("scheme", list(SCHEMES))
def test_schemes_reach_exactly_their_documented_degree(scheme: str) -> None:
    """SCHEMES states each scheme's degree; a fixed 9-point non-uniform grid confirms it both ways."""
    t = np.array([0.0, 0.1, 0.35, 0.4, 0.7, 1.0, 1.1, 1.6, 2.0])
    degree = SCHEMES[scheme] if SCHEMES[scheme] is not None else t.size - 1
    at = np.linspace(0.0, 2.0, 41)
    ones = np.ones((degree + 2, 1))
    assert max_error(scheme, t, ones[: degree + 1], at) <= RTOL
    assert max_error(scheme, t, ones, at) > NOT_EXACT


# --- samples are returned exactly ----------------------------------------------------------------------

finite = st.floats(allow_nan=False, allow_infinity=False)


# grids like [0.0, 5e-324] are valid but their barycentric weights overflow (a warning when the
# interpolant is built); only the sample times themselves are evaluated here
@pytest.mark.filterwarnings("ignore:divide by zero:RuntimeWarning")
@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@props
@given(
    st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=10, unique=True).map(sorted),
    CHANNELS,
    st.sampled_from(list(SCHEMES)),
    st.data(),
)
def test_interpolation_at_sample_times_returns_the_samples(
    grid: list[float], m: int, scheme: str, data: st.DataObject
) -> None:
    n = len(grid)
    values = np.array(data.draw(st.lists(finite, min_size=n * m, max_size=n * m))).reshape(n, m)
    seg = Segment(grid, values)
    f = seg.interpolant(scheme)
    for i, ti in enumerate(seg.times):
        np.testing.assert_array_equal(f(ti), values[i], err_msg=f"{scheme} at t[{i}]={ti!r}")
        np.testing.assert_array_equal(f(float(ti)), values[i])


def test_linear_last_sample_is_exact() -> None:
    """a + 1.0 * (b - a) is not always b in floating point: 0.2 + (0.9 - 0.2) == 0.9000000000000001."""
    seg = Segment([0.0, 1.0], [[0.2], [0.9]])
    assert seg(1.0, "linear")[0] == 0.9


@pytest.mark.parametrize("scheme", list(SCHEMES))
def test_huge_samples_do_not_overflow(scheme: str) -> None:
    seg = Segment([0.0, 1.0, 2.0, 3.0], [[1e308], [-1e308], [1e308], [-1.5e308]])
    for i, t in enumerate(seg.times):
        assert seg(t, scheme)[0] == seg.values[i, 0]
    if scheme == "linear":
        assert seg(0.5, scheme)[0] == 0.0 and seg(2.5, scheme)[0] == -0.25e308


@pytest.mark.parametrize("scheme", ["cubic", "lagrange"])
def test_times_a_rounding_error_away_from_a_sample(scheme: str) -> None:
    """Between samples, arbitrarily close to one: still finite and equal to the sample to rounding."""
    t = np.array([0.0, 0.25, 0.5, 1.0, 1.5])
    values = np.array([[1.0, -2.0], [2.0, 0.5], [3.0, 1.0], [0.5, 4.0], [-1.0, 2.0]])
    f = Segment(t, values).interpolant(scheme)
    for i, ti in enumerate(t):
        for x in (ti + 5e-324, ti - 5e-324, math.nextafter(ti, math.inf), math.nextafter(ti, -math.inf)):
            if t[0] <= x <= t[-1]:
                np.testing.assert_allclose(f(x), values[i], rtol=1e-12, atol=1e-12)


# --- many times in one call ---------------------------------------------------------------------------


def _probe_times(grid: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Every sample time, its float neighbours, midpoints, random inner times, and times outside the grid."""
    span = grid[-1] - grid[0] if grid.size > 1 else 1.0
    near = np.concatenate([np.nextafter(grid, np.inf), np.nextafter(grid, -np.inf)])
    mids = 0.5 * (grid[1:] + grid[:-1])
    inner = rng.uniform(grid[0], grid[-1], 60) if grid.size > 1 else grid
    outside = np.concatenate([grid[0] - span * rng.uniform(0.0, 1.5, 8), grid[-1] + span * rng.uniform(0.0, 1.5, 8)])
    ts = np.concatenate([grid, near, mids, inner, outside, grid[::-1]])
    return rng.permutation(ts)  # unsorted, with repeats: each time is evaluated on its own


@pytest.mark.parametrize("scheme", list(SCHEMES))
@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 8])
@pytest.mark.parametrize("uniform", [True, False])
@pytest.mark.parametrize("m", [4, 20])  # (one time of up to 16 channels is interpolated on Python floats)
def test_an_array_of_times_gives_the_scalar_rows_bit_for_bit(scheme: str, n: int, uniform: bool, m: int) -> None:
    rng = np.random.default_rng(1000 * n + uniform)
    grid = np.linspace(3.0, 3.4, n) if uniform else np.sort(rng.uniform(-2.0, 5.0, n))
    values = rng.normal(size=(n, m)) * np.resize([1.0, 1e-8, 1e6, 7e3], m)
    f = Segment(grid, values).interpolant(scheme)
    ts = _probe_times(grid, rng)
    with np.errstate(all="ignore"):  # n = 8 lagrange far outside the grid: large, still finite
        many = f(ts)
        one_by_one = np.array([f(float(t)) for t in ts])
    assert many.shape == (ts.size, m)
    assert many.tobytes() == one_by_one.tobytes()  # identical bits, signed zeros included
    for i, t in enumerate(grid):  # the samples themselves, as a batch of one and inside the batch
        assert f(np.array([t])).tobytes() == values[i : i + 1].tobytes()
    np.testing.assert_array_equal(many[np.isin(ts, grid)], values[np.searchsorted(grid, ts[np.isin(ts, grid)])])


@pytest.mark.parametrize("scheme", list(SCHEMES))
def test_array_shapes(scheme: str) -> None:
    f = Segment([0.0, 0.1, 0.2, 0.3, 0.4], np.arange(10.0).reshape(5, 2)).interpolant(scheme)
    assert f(0.05).shape == (2,) and f(np.float64(0.05)).shape == (2,) and f(np.array(0.05)).shape == (2,)
    assert f(np.array([0.05, 0.15, 0.3])).shape == (3, 2)
    assert f(np.empty(0)).shape == (0, 2)
    assert f([0.05, 0.35]).tobytes() == np.array([f(0.05), f(0.35)]).tobytes()


@pytest.mark.parametrize("scheme", list(SCHEMES))
def test_interpolants_on_one_grid_share_weights_never_values(scheme: str) -> None:
    """The weights kept per (scheme, grid, times) serve other values on that grid, and only that grid."""
    n = 9 if scheme == "lagrange" else 65
    grid = np.linspace(10.0, 14.48, n)
    ts = np.sort(np.concatenate([grid, 0.5 * (grid[1:] + grid[:-1]), [9.9, 14.6]]))  # RK-like times, and beyond
    rng = np.random.default_rng(7)
    v1, v2 = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    moved = grid.copy()
    moved[n // 2] += 0.3 * (grid[1] - grid[0])  # another grid, the same times asked for
    first = interpolant(grid, v1, scheme)(ts)
    second = interpolant(grid, v2, scheme)(ts)
    other = interpolant(moved, v2, scheme)(ts)
    signals._KEPT_WEIGHTS.clear()
    for got, (g, v) in ((first, (grid, v1)), (second, (grid, v2)), (other, (moved, v2))):
        fresh = interpolant(g, v, scheme)(ts)
        signals._KEPT_WEIGHTS.clear()
        assert got.tobytes() == fresh.tobytes()
        assert got.tobytes() == np.array([interpolant(g, v, scheme)(float(t)) for t in ts]).tobytes()
    assert not np.allclose(second, other)  # the moved sample matters: a key without the grid would miss it


@pytest.mark.parametrize("scheme", list(SCHEMES))
def test_kept_weights_serve_values_of_any_width(scheme: str) -> None:
    """Kept weights keep their coefficients repeated per channel count: values of another width on the same grid
    and times get their own, bit for bit what the scalar form gives. Past WIDE_MAX values they are not kept."""
    grid = np.linspace(3.0, 3.4, 6)
    ts = np.sort(np.concatenate([grid, 0.5 * (grid[1:] + grid[:-1])]))  # RK-like times, samples among them
    rng = np.random.default_rng(3)
    signals._KEPT_WEIGHTS.clear()
    for m in (3, 1, 6, 3):
        v = rng.normal(size=(grid.size, m))
        got = interpolant(grid, v, scheme)(ts)
        assert got.tobytes() == np.array([interpolant(grid, v, scheme)(float(t)) for t in ts]).tobytes()
    (kept,) = signals._KEPT_WEIGHTS.values()
    assert sorted(kept.wide) == [3, 6]  # one channel: the coefficients have that shape already, no copy
    many = signals.WIDE_MAX // kept.coef.size + 1  # channels past the bound: broadcast, the same bits
    v = rng.normal(size=(grid.size, many))
    got = interpolant(grid, v, scheme)(ts)
    assert got.tobytes() == np.array([interpolant(grid, v, scheme)(float(t)) for t in ts]).tobytes()
    assert sorted(kept.wide) == [3, 6]


@pytest.mark.parametrize("shape", [(0,), (1,), (6,), (16,), (17,), (200,), (5, 3), (1, 1)])
@pytest.mark.parametrize("bad", [None, np.nan, np.inf, -np.inf])
def test_all_finite_says_what_numpy_says(shape: tuple[int, ...], bad: float | None) -> None:
    """On Python floats for a short vector, in one reduction for the rest: NumPy's answer either way."""
    for where in range(max(math.prod(shape), 1) if bad is not None else 1):
        a = (1.7e308 * np.linspace(-1.0, 1.0, math.prod(shape))).reshape(shape)  # (a sum would overflow)
        if bad is not None and a.size:
            a.reshape(-1)[where] = bad
        assert signals.all_finite(a) is bool(np.isfinite(a).all())


def test_the_kept_weights_stay_bounded() -> None:
    grid = np.linspace(0.0, 0.4, 5)
    ts = np.linspace(0.0, 0.4, 9)
    for i in range(3 * signals.KEPT_WEIGHTS_MAX):
        interpolant(grid + i, np.ones((5, 2)), "linear")(ts + i)
        assert len(signals._KEPT_WEIGHTS) <= signals.KEPT_WEIGHTS_MAX


def test_lagrange_through_too_many_samples_is_refused_where_it_would_give_nan() -> None:
    """One polynomial through 500 samples: its weights underflowed and a constant input came out NaN (after 37 s
    at 10,000 samples). The runtime refuses it as bad_value, and a scenario's settings refuse it at load."""
    from cosim.contract import SubsimError
    from cosim.coupler.relaxation import Settings
    from cosim.handles import InProcessHandle
    from cosim.signals import LAGRANGE_MAX_SAMPLES
    from subsims.integrator.subsim import Integrator

    h = InProcessHandle(Integrator())
    h.configure({})
    n = LAGRANGE_MAX_SAMPLES
    t = np.linspace(0.0, 0.1, n)
    y = h.run_interval(t, {"u": np.ones((n, 1))}, interp="lagrange").outputs["y"]
    assert np.isfinite(y).all() and abs(y[-1, 0] - 0.1) < 1e-12
    t = np.linspace(0.0, 0.1, n + 1)
    with pytest.raises(SubsimError, match=r"\[bad_value\] interp: 'lagrange' puts one polynomial .* n = 65 samples; "
                                          r"at most 64 .*use 'cubic'"):
        h.run_interval(t, {"u": np.ones((n + 1, 1))}, interp="lagrange")
    with pytest.raises(ValueError, match="at most 64"):
        Settings(interval=0.1, samples=65, interp="lagrange")


@pytest.mark.parametrize("scheme", ["lagrange", "cubic"])
def test_one_time_far_outside_the_grid_gives_what_the_batch_gives(scheme: str) -> None:
    """On Python floats the scalar form raised ZeroDivisionError where the weights sum to zero (t = 1e20 on a grid
    0 .. 0.2); the batch form gives NaN there (a red team)."""
    f = Segment(np.linspace(0.0, 0.2, 3 if scheme == "lagrange" else 6), np.ones((3 if scheme == "lagrange" else 6,
                                                                              2))).interpolant(scheme)
    with np.errstate(all="ignore"):
        assert f(1e20).tobytes() == f(np.array([1e20]))[0].tobytes()
