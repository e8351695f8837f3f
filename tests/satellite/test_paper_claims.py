"""The paper's claims about its satellite (spec §10), on shortened runs over Zenoh with real processes.

Every run below is a real ``run_scenario(..., inprocess=False)`` of ``scenarios/satellite/case{1,2}.toml``:
three subsim processes per run, RF-C (centralized) and RF-D (distributed), against the RK-U unified
reference (``cosim.unified.run_unified``) written in the same columns.

Run length: 2,000 s of problem time (5,000 intervals per run), the issue's minimum; the six coupled
runs go three at a time and take ~3-5 min of wall time on 2 cores.

Claims and the bounds used (measured values at 2,000 s in the comments):

* Cases 1 and 2 "identical ... for all solution approaches" (RF-C, RF-D, RK-U): Euler angles within
  1e-8 deg, except case 2's uncontrolled z axis; the bounds used are 10x the measured deviations
  (``ANGLE_BOUND``, ``POSITION_BOUND``), tighter than that. Its angle is the
  integral of the torque errors that the paper blames for case 3's divergence (the feedback is a
  linear interpolant of 0.1 s samples inside the RK4 stages, spec §3.4); with no control to hold it,
  that error grows like t^2 and passes 1e-8 deg at ~370 s (4.3e-7 deg at 2,000 s). It gets a 4.3e-6 deg
  bound, and ``test_case2_free_axis_deviation_is_the_interpolation_error`` shows the deviation is that
  O(h^2) interpolation error: halving the sample spacing quarters it, and with cubic interpolation of
  the fed-back signals (the same scenario with ``interp = "cubic"``) both methods are within 1e-8 deg
  on every axis (measured 1.7e-12 deg): ``test_case2_within_1e8_deg_on_every_axis_with_cubic_feedback``.
* RF-C and RF-D "for all practical purposes ... identical": within 1e-14 deg and 1e-12 m (measured
  ~1e-15 deg, 0 m), and far closer to each other than to RK-U.
* "The maximum number of recursion stages is typically three, one of which could arguably be said to
  serve no purpose other than to confirm satisfaction of error tolerances": see ``test_stages``.
"""

from __future__ import annotations

import csv
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main as cosim_main
from cosim.results import read_results
from cosim.runner import RunReport, run_scenario
from cosim.scenario import ScenarioError, load
from cosim.unified import run_unified

pytestmark = pytest.mark.paper

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "scenarios" / "satellite"
CASES = ("case1", "case2")
COUPLED = ("centralized", "distributed")

# Largest allowed deviation from RK-U, per Euler angle component (deg) and for the position (m): 10x what is
# measured at 2,000 s, so a coupling that got worse by an order of magnitude fails even while it still met
# the paper's "identical" (taken as 1e-8 deg, which every bound below also keeps except case 2's free z axis)
PAPER_ANGLE = 1e-8  # deg
ANGLE_BOUND = {"case1": (6e-10, 3e-9, 1e-9),  # measured 6e-11, 3e-10, 1e-10 deg at 2,000 s
               "case2": (1e-10, 2e-9, 4.3e-6)}  # measured 1e-11, 2e-10, 4.3e-7 deg (z uncontrolled)
POSITION_BOUND = {"case1": 1.4e-6, "case2": 3.9e-7}  # m; measured 1.4e-7 (case 1), 3.9e-8 (case 2)


def quiet(_: str) -> None:
    pass


CUBIC = "case2-cubic"  # case 2 with cubic interpolation of the fed-back signals


def cubic_case2(out: Path) -> Path:
    text = (SCENARIOS / "case2.toml").read_text()
    assert '\ninterp = "linear"' in text
    path = out / f"{CUBIC}.toml"
    path.write_text(text.replace('\ninterp = "linear"', '\ninterp = "cubic"'))
    return path


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """{(case, method): (report, columns, data)} for cases 1-2 x RF-C/RF-D/RK-U over ``stop`` seconds.

    The coupled runs go three at a time (each waits on Zenoh round trips much of the time).
    """
    stop = 2000.0
    out = tmp_path_factory.mktemp(f"paper-{stop:g}s")
    files = {case: SCENARIOS / f"{case}.toml" for case in CASES} | {CUBIC: cubic_case2(out)}

    def coupled(case: str, method: str) -> RunReport:
        return run_scenario(load(files[case]), method=method, stop=stop,
                            output=out / f"{case}-{method}.csv", inprocess=False, progress=False, log=quiet)

    reports: dict[tuple[str, str], RunReport] = {}
    with ThreadPoolExecutor(max_workers=3) as pool:  # more only adds contention on 2 cores
        pending = {(c, m): pool.submit(coupled, c, m) for c in files for m in COUPLED}
        for case in CASES:
            reports[case, "unified"] = run_unified(load(SCENARIOS / f"{case}.toml"), stop=stop,
                                                   output=out / f"{case}-unified.csv")
        reports.update({k: f.result() for k, f in pending.items()})
    result = {}
    for key, report in reports.items():
        columns, data = read_results(report.output)
        result[key] = (report, columns, data)
    result["stop"] = stop
    return result


def select(columns: list[str], data: np.ndarray, signal: str) -> np.ndarray:
    return data[:, [columns.index(f"{signal}[{i}]") for i in range(3)]]


def euler_deg(run: tuple) -> np.ndarray:
    """The attitude subsim's (unlimited) Euler angles, deg."""
    _, columns, data = run
    return np.degrees(select(columns, data, "attitude.phi"))


def position(run: tuple) -> np.ndarray:
    _, columns, data = run
    return select(columns, data, "orbit.R")


@pytest.mark.slow
@pytest.mark.zenoh
def test_runs_cover_the_same_samples(runs: dict) -> None:
    stop = runs["stop"]
    ref_report, ref_columns, ref = runs["case1", "unified"]
    assert ref_report.method == "unified"
    n = round(stop / 0.1) + 1  # 0.1 s samples, both ends
    for case in CASES:
        for method in (*COUPLED, "unified"):
            report, columns, data = runs[case, method]
            assert report.method == method
            assert columns == ref_columns  # same columns, so results compare column by column
            assert data.shape == (n, len(ref_columns))
            np.testing.assert_array_equal(data[:, 0], ref[:, 0])  # identical time column
            assert data[-1, 0] == pytest.approx(stop)
            assert np.all(np.isfinite(data))


@pytest.mark.slow
@pytest.mark.zenoh
@pytest.mark.parametrize("method", COUPLED)
@pytest.mark.parametrize("case", CASES)
def test_recursive_feedback_matches_unified(runs: dict, case: str, method: str) -> None:
    """Spec §10: cases 1 and 2 'identical ... for all solution approaches (RF-C, RF-D, and RK-U)'."""
    rf, rku = runs[case, method], runs[case, "unified"]
    d_angle = np.max(np.abs(euler_deg(rf) - euler_deg(rku)), axis=0)
    d_pos = np.max(np.abs(position(rf) - position(rku)))
    assert np.all(d_angle <= ANGLE_BOUND[case]), f"Euler angle deviation {d_angle} deg > {ANGLE_BOUND[case]}"
    assert d_pos <= POSITION_BOUND[case], f"position deviation {d_pos} m"
    # two different numerical processes (interpolated vs stage-exact aerodynamics), not one file twice
    assert np.max(d_angle) > 0.0 and d_pos > 0.0
    # and the comparison is not vacuous: the attitude really moves (case 2's z axis drifts freely)
    assert np.max(np.abs(euler_deg(rku))) > 1e3 * np.max(ANGLE_BOUND[case])


@pytest.mark.slow
@pytest.mark.zenoh
@pytest.mark.parametrize("method", COUPLED)
def test_case2_within_1e8_deg_on_every_axis_with_cubic_feedback(runs: dict, method: str) -> None:
    """With the interpolation error removed from the fed-back loads, case 2 meets the 1e-8 deg claim on the
    free z axis too: the deviation at paper settings is the interpolation, not the coupling."""
    rf, rku = runs[CUBIC, method], runs["case2", "unified"]
    d_angle = np.max(np.abs(euler_deg(rf) - euler_deg(rku)), axis=0)
    assert np.all(d_angle <= PAPER_ANGLE), f"Euler angle deviation {d_angle} deg"
    assert np.all(d_angle <= 2e-11), f"Euler angle deviation {d_angle} deg"  # measured 1.7e-12 deg
    assert np.max(np.abs(position(rf) - position(rku))) <= POSITION_BOUND["case2"]
    paper = np.max(np.abs(euler_deg(runs["case2", method]) - euler_deg(rku)), axis=0)
    assert d_angle[2] < 1e-2 * paper[2]


@pytest.mark.slow
@pytest.mark.zenoh
@pytest.mark.parametrize("case", CASES)
def test_centralized_and_distributed_agree(runs: dict, case: str) -> None:
    """Spec §10: RF-C and RF-D 'for all practical purposes ... identical' (measured ~1e-15 deg, 0 m)."""
    c, d, u = runs[case, "centralized"], runs[case, "distributed"], runs[case, "unified"]
    d_angle = np.max(np.abs(euler_deg(c) - euler_deg(d)))
    d_pos = np.max(np.abs(position(c) - position(d)))
    assert d_angle <= 1e-14 and d_pos <= 1e-12, (d_angle, d_pos)  # measured ~1e-15 deg, 0 m
    # closer to each other than either is to the unified reference
    to_unified = np.max(np.abs(euler_deg(d) - euler_deg(u)))
    assert d_angle <= 1e-3 * to_unified


def stage_counts(report: RunReport) -> Counter:
    """Stages per interval from the diagnostics file (stage 0 included): {stages: intervals}."""
    with report.diagnostics.open() as f:
        return Counter(int(row["stages"]) for row in csv.DictReader(f))


def paper_nit(method: str, stages: int) -> int:
    """The ``nit`` the listings write per interval, from our stage count (stage 0 included).

    RF-D (spec §5.3): nit is incremented at the top of the recursion loop, so at convergence it is the
    index of the last stage: stages 0..nit, nit = stages - 1. RF-C (spec §4.1): nit is incremented after
    each failed check only, and the first check follows stage 1: nit = stages - 2.
    """
    return stages - 1 if method == "distributed" else stages - 2


@pytest.mark.slow
@pytest.mark.zenoh
@pytest.mark.parametrize("case", CASES)
def test_stages(runs: dict, case: str) -> None:
    """Spec §10: 'the maximum number of recursion stages is typically three, one of which could arguably
    be said to serve no purpose other than to confirm satisfaction of error tolerances'.

    What the paper counts: RF-D runs stages 0, 1, 2 (listing nit = 2). Stage 2 only confirms: its
    feedback equals stage 1's to within 1e-14. That is three recursion stages, one of them confirming.
    RF-C starts stage 0 with *every* coupling zero (also R for the gravity gradient and V for the
    aerodynamics, spec §4.1 and §5.5), so information needs two more stages to go round its loop:
    it runs stages 0..4, and its listing writes nit = 3 failed checks. Both methods therefore report
    'three' in the paper's own terms; our diagnostics count 3 (RF-D) and 5 (RF-C) stage runs.
    """
    total = round(runs["stop"] / 0.4)
    rfd, rfc = stage_counts(runs[case, "distributed"][0]), stage_counts(runs[case, "centralized"][0])
    assert sum(rfd.values()) == sum(rfc.values()) == total
    assert rfd == runs[case, "distributed"][0].summary.stages  # the diagnostics say what the run did
    # RF-D: typically 3 stages (0, 1, 2), listing nit 2; never more than one extra
    assert rfd.most_common(1)[0][0] == 3 and paper_nit("distributed", 3) == 2
    assert rfd[3] >= 0.99 * total and max(rfd) <= 4
    # RF-C: typically 5 stage runs, listing nit 3
    assert rfc.most_common(1)[0][0] == 5 and paper_nit("centralized", 5) == 3
    assert rfc[5] >= 0.99 * total and max(rfc) <= 6


@pytest.mark.slow
def test_case2_free_axis_deviation_is_the_interpolation_error(tmp_path: Path) -> None:
    """The RF vs RK-U difference is the paper's stated cause (spec §10): linear interpolation of the fed-back
    loads over the 0.1 s sample spacing inside the RK4 stages, an O(h^2) error. Halving the spacing (9
    samples per 0.4 s interval, 0.05 s RK4 steps in both RF-D and RK-U) quarters it (measured ratio 4.0).
    In-process: the numbers are bit-identical to a Zenoh run (tests/test_oscillator.py) and this is physics.
    """
    base = (SCENARIOS / "case2.toml").read_text()
    assert "\nsamples = 5 " in base
    deviation = {}
    for samples in (5, 9):
        path = tmp_path / f"case2-{samples}.toml"
        path.write_text(base.replace("\nsamples = 5 ", f"\nsamples = {samples} "))
        scenario = load(path)
        assert scenario.settings_for().samples == samples
        rf = run_scenario(scenario, method="distributed", stop=400.0, output=tmp_path / f"d{samples}.csv",
                          inprocess=True, progress=False, log=quiet)
        rku = run_unified(scenario, stop=400.0, output=tmp_path / f"u{samples}.csv")
        a, b = read_results(rf.output), read_results(rku.output)
        deviation[samples] = np.max(np.abs(euler_deg((rf, *a))[:, 2] - euler_deg((rku, *b))[:, 2]))
    assert deviation[5] > 1e-9  # measured 1.2e-8 deg at 400 s
    assert deviation[9] / deviation[5] == pytest.approx(0.25, rel=0.1)


def test_describe_shows_rfd_feedback_is_aero_force_and_torque(capsys: pytest.CaptureFixture) -> None:
    """Spec §5.1: only the aero force (to the orbit) and torque (to the attitude) cross the recursive
    transfer point in RF-D: 6 scalar signals."""
    assert cosim_main(["describe", str(SCENARIOS / "case1.toml")]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if "feedback edges" in ln)
    assert line.strip() == ("feedback edges (6 scalar signals): aero.force, attitude.phi -> orbit.f_aero; "
                            "aero.torque, aero.force -> attitude.torque")
    assert "order (given): orbit -> attitude -> aero" in out


def test_unified_needs_a_unified_function(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=r"no \[unified\] function"):
        run_unified(load(ROOT / "scenarios" / "oscillator.toml"), stop=0.1, output=tmp_path / "x.csv")


@pytest.mark.parametrize("case", ["case1", "case2", "case3"])
def test_scenarios_hold_the_cases_params(case: str) -> None:
    """The TOML files write out subsims/satellite/cases.py and the paper's settings (spec §3.5, §9.1)."""
    from subsims.satellite.cases import CASES as PARAMS

    sc = load(SCENARIOS / f"{case}.toml")
    for name in ("orbit", "attitude", "aero"):
        assert sc.subsims[name].params == PARAMS[case][name]
    torque = next(c for c in sc.couplings if str(c.target) == "attitude.torque")
    assert dict(torque.params) == PARAMS[case]["transfer"]
    assert sc.default_method == "distributed" and sc.stop == 60000.0
    assert sc.unified is not None and sc.unified.function == "subsims.satellite.reference:unified_scenario"
    c, d = sc.settings_for("centralized"), sc.settings_for("distributed")
    assert (c.tol.rel, c.tol.abs, d.tol.rel, d.tol.abs) == (1e-12, 1e-12, 1e-14, 1e-14)
    assert list(d.order) == ["orbit", "attitude", "aero"]
    for s in (c, d):
        assert (s.interval, s.samples, s.first_guess, s.interp, s.max_stages) == (0.4, 5, "zero", "linear", 100)
