"""``cosim plot``: PNGs from result files, satellite figures and the generic per-signal plots."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.image import imread  # noqa: E402

from cosim import plot as cosim_plot  # noqa: E402
from cosim.cli import main as cosim_main  # noqa: E402
from cosim.plot import PlotError, envelope, plot_command, plot_files  # noqa: E402
from cosim.results import read_results  # noqa: E402
from cosim.scenario import load  # noqa: E402
from cosim.unified import run_unified  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def assert_real_png(path: Path) -> None:
    assert path.exists(), path
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > 10_000, f"{path} is suspiciously small"
    img = imread(path)
    assert img.shape[0] > 300 and img.shape[1] > 600
    # something drawn: many distinct colours, not a blank canvas
    assert len(np.unique(img.reshape(-1, img.shape[-1])[:, :3].round(2), axis=0)) > 20


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch) -> dict[str, dict]:
    """What every saved figure shows, by file name: title, axis labels, and each line's label and data."""
    from matplotlib.figure import Figure

    seen: dict[str, dict] = {}
    save = Figure.savefig

    def record(fig: Figure, path, *args, **kwargs):  # noqa: ANN001, ANN202 - matplotlib's signature
        axes = fig.get_axes()
        name = Path(getattr(path, "name", path)).name  # a path, or the file object of an atomic write:
        if name.startswith(".") and ".tmp-" in name:  # ".<name>.tmp-<pid>" becomes <name>
            name = name[1:].rsplit(".tmp-", 1)[0]
        seen[name] = {
            "title": axes[0].get_title(),
            "xlabel": axes[-1].get_xlabel(),
            "ylabels": [ax.get_ylabel() for ax in axes],
            "lines": [[(ln.get_label(), np.asarray(ln.get_xdata(), float), np.asarray(ln.get_ydata(), float))
                       for ln in ax.get_lines()] for ax in axes],
            "colors": [[ln.get_color() for ln in ax.get_lines()] for ax in axes],
        }
        return save(fig, path, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", record)
    return seen


def assert_colours_drawn(path: Path, colours: list[str]) -> None:
    """Every line colour appears in the PNG's pixels (to within 8 of 255 per channel: antialiasing)."""
    from matplotlib.colors import to_rgb

    img = imread(path)[:, :, :3].reshape(-1, 3)
    for c in colours:
        assert np.any(np.all(np.abs(img - np.array(to_rgb(c))) < 8 / 255, axis=1)), (path.name, c)


def dcm321(phi_deg: np.ndarray) -> np.ndarray:
    """z-y-x (3-2-1) rotation matrices of rows of angles (phi_x, phi_y, phi_z) in deg, written here."""
    x, y, z = np.radians(phi_deg).T
    cx, sx, cy, sy, cz, sz = np.cos(x), np.sin(x), np.cos(y), np.sin(y), np.cos(z), np.sin(z)
    return np.stack([np.stack([cy * cz, cy * sz, -sy], -1),
                     np.stack([sx * sy * cz - cx * sz, sx * sy * sz + cx * cz, sx * cy], -1),
                     np.stack([cx * sy * cz + sx * sz, cx * sy * sz - sx * cz, cx * cy], -1)], 1)


@pytest.fixture(scope="module")
def satellite_results(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    out = tmp_path_factory.mktemp("sat")
    files = []
    for case in ("case1", "case3"):
        report = run_unified(load(ROOT / "scenarios" / "satellite" / f"{case}.toml"), stop=60.0,
                             output=out / f"{case}-unified.csv")
        files.append(report.output)
    return files


def generic_result(path: Path, shift: float = 0.0) -> Path:
    t = np.linspace(0.0, 2.0, 201)
    rows = np.column_stack([t, np.cos(2 * np.pi * t + shift), np.sin(2 * np.pi * t), t**2])
    header = "time,m1.u[0],m1.v[0],m2.x[0]"
    np.savetxt(path, rows, delimiter=",", header=header, comments="")
    return path


@pytest.mark.slow
def test_satellite_figures(satellite_results: list[Path], tmp_path: Path, drawn: dict[str, dict]) -> None:
    # what `cosim plot results/*` passes: the diagnostics and units files beside the results (skipped)
    beside = [p.with_name(p.name + s) for p in satellite_results for s in (".diag.csv", ".meta.json")]
    assert all(p.exists() for p in beside)
    args = argparse.Namespace(results=[*satellite_results, *beside], out=tmp_path / "png", signals=None)
    assert plot_command(args) == 0
    for name in ("satellite-euler", "satellite-rates", "satellite-altitude", "orbit.R", "orbit.V",
                 "attitude.phi", "attitude.omega", "aero.force", "aero.torque"):
        assert_real_png(tmp_path / "png" / f"{name}.png")
        shown = drawn[f"{name}.png"]
        assert shown["xlabel"] == "time (s)"
        assert_colours_drawn(tmp_path / "png" / f"{name}.png", [c for cs in shown["colors"] for c in cs])
        for lines in shown["lines"]:  # one line per result file, labelled with its name
            assert [label for label, _, _ in lines] == ["case1-unified", "case3-unified"]
    # what is drawn is the results' data, transformed as the captions say (computed here from the CSV files)
    data = {}
    for path in satellite_results:
        cols, values = read_results(path)
        data[path.stem] = {c: values[:, cols.index(c)] for c in cols}
    euler = drawn["satellite-euler.png"]
    assert euler["ylabels"] == ["phi_x (deg)", "phi_y (deg)", "phi_z (deg)"]
    rates, altitude = drawn["satellite-rates.png"], drawn["satellite-altitude.png"]
    assert rates["ylabels"] == ["omega_x (deg/s)", "omega_y (deg/s)", "omega_z (deg/s)"]
    assert altitude["ylabels"] == ["altitude (km)"] and altitude["title"] == "Altitude"
    for j, stem in enumerate(("case1-unified", "case3-unified")):
        d = data[stem]
        t = d["time"]
        phi = np.degrees(np.column_stack([d[f"attitude.phi[{i}]"] for i in range(3)]))
        shown = np.column_stack([euler["lines"][i][j][2][~np.isnan(euler["lines"][i][j][2])] for i in range(3)])
        np.testing.assert_array_equal(euler["lines"][0][j][1][~np.isnan(euler["lines"][0][j][1])], t)
        # range-limited: phi_x, phi_z in (-180, 180], phi_y in [-90, 90], and the same attitude as the state angles
        assert np.all(np.abs(shown[:, [0, 2]]) <= 180.0) and np.all(np.abs(shown[:, 1]) <= 90.0)
        np.testing.assert_allclose(dcm321(shown), dcm321(phi), rtol=0, atol=1e-12)
        for i in range(3):
            np.testing.assert_allclose(rates["lines"][i][j][2], np.degrees(d[f"attitude.omega[{i}]"]), rtol=1e-15)
            np.testing.assert_array_equal(drawn["orbit.R.png"]["lines"][i][j][2], d[f"orbit.R[{i}]"])
        radius = np.sqrt(sum(d[f"orbit.R[{i}]"] ** 2 for i in range(3)))
        np.testing.assert_allclose(altitude["lines"][0][j][2], radius / 1000.0 - 6367.65, rtol=0, atol=1e-9)


@pytest.mark.slow  # pays for the two 60-s unified satellite runs when test_satellite_figures is deselected
def test_time_window(satellite_results: list[Path], tmp_path: Path) -> None:
    written = plot_files(satellite_results, tmp_path, window=(20.0, 40.0))
    assert tmp_path / "satellite-euler.png" in written
    with pytest.raises(PlotError, match="inside the window"):
        plot_files(satellite_results, tmp_path, window=(100.0, 200.0))
    for backwards in ((40.0, 20.0), (float("nan"), 40.0)):  # not "no samples": the span itself is wrong
        with pytest.raises(PlotError, match="give a time span T0 < T1"):
            plot_files(satellite_results, tmp_path, window=backwards)


def test_generic_signals_via_cli(tmp_path: Path, capsys: pytest.CaptureFixture, drawn: dict[str, dict]) -> None:
    a, b = generic_result(tmp_path / "a.csv"), generic_result(tmp_path / "b.csv", shift=0.5)
    assert cosim_main(["plot", str(a), str(b), "--out", str(tmp_path / "png")]) == 0
    printed = capsys.readouterr().out.split()
    assert sorted(Path(p).name for p in printed) == ["m1.u.png", "m1.v.png", "m2.x.png"]
    for p in printed:
        assert_real_png(Path(p))
        assert_colours_drawn(Path(p), [c for cs in drawn[Path(p).name]["colors"] for c in cs])
    # each figure: one panel, titled and labelled by its signal, one line per file with that file's data
    t = np.linspace(0.0, 2.0, 201)
    expected = {"m1.u": [np.cos(2 * np.pi * t), np.cos(2 * np.pi * t + 0.5)], "m1.v": [np.sin(2 * np.pi * t)] * 2,
                "m2.x": [t**2] * 2}
    for signal, ys in expected.items():
        shown = drawn[f"{signal}.png"]
        assert shown["title"] == signal and shown["ylabels"] == [f"{signal}[0]"] and shown["xlabel"] == "time (s)"
        assert [label for label, _, _ in shown["lines"][0]] == ["a", "b"]
        for (_, x, y), y_expected in zip(shown["lines"][0], ys):
            np.testing.assert_allclose(x, t, rtol=0, atol=1e-15)
            np.testing.assert_allclose(y, y_expected, rtol=0, atol=1e-15)
    assert not (tmp_path / "png" / "satellite-euler.png").exists()  # not a satellite result


def test_signal_selection(tmp_path: Path) -> None:
    a = generic_result(tmp_path / "a.csv")
    written = plot_files([a], tmp_path / "png", signals=["m1.u"])
    assert [p.name for p in written] == ["m1.u.png"]
    with pytest.raises(PlotError, match="nothing matches"):
        plot_files([a], tmp_path / "png", signals=["nope"])


def test_errors_are_reported(tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch) -> None:
    assert cosim_main(["plot", str(tmp_path / "missing.csv"), "--out", str(tmp_path)]) == 2
    assert "not found" in capsys.readouterr().err
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n")
    assert cosim_main(["plot", str(bad), "--out", str(tmp_path)]) == 2
    assert "not a cosim result file" in capsys.readouterr().err
    # a scenario, and a results file's units alone (a newcomer probe: NumPy's parse error; 'given alone, a
    # diagnostics file is plotted')
    scenario = tmp_path / "s.toml"
    scenario.write_text('name = "x"\n')
    assert cosim_main(["plot", str(scenario), "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"cosim plot: {scenario}: a .toml file, not results: plot the .csv or .npz a " \
                                      "run wrote (cosim run prints where, after 'results:')\n"
    units = generic_result(tmp_path / "r.csv").with_name("r.csv.meta.json")
    assert cosim_main(["plot", str(units), "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == f"cosim plot: no result files given (only files beside them): " \
                                                       f"cosim plot {tmp_path / 'r.csv'}"
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # as if not installed
    assert cosim_main(["plot", str(generic_result(tmp_path / "a.csv")), "--out", str(tmp_path)]) == 2
    assert "pip install 'cosim[plot]'" in capsys.readouterr().err


class _Entry:
    """Stands in for an importlib.metadata entry point of the ``cosim.figures`` group."""

    def __init__(self, name: str, load) -> None:
        self.name, self.value, self.load = name, f"tests:{name}", load


def test_figure_providers_are_called_and_a_broken_one_is_named_and_skipped(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    seen = []

    def figures(results, out):
        seen.append([r.label for r in results])
        return [out / "mine.png"]

    def broken():
        raise ImportError("no module named 'gone'")

    a = generic_result(tmp_path / "a.csv")
    monkeypatch.setattr(cosim_plot, "entry_points", lambda group: [_Entry("mine", lambda: figures)])
    written = plot_files([a], tmp_path / "png")
    assert seen == [["a"]] and written[0] == tmp_path / "png" / "mine.png"
    assert plot_files([a], tmp_path / "png", signals=["m1.u"])[0].name == "m1.u.png" and len(seen) == 1
    monkeypatch.setattr(cosim_plot, "entry_points", lambda group: [_Entry("broken", broken)])
    capsys.readouterr()
    assert [p.name for p in plot_files([a], tmp_path / "png")] == ["m1.u.png", "m1.v.png", "m2.x.png"]
    assert "figure provider 'broken' (tests:broken), which failed to load: no module" in capsys.readouterr().err


def test_envelope_keeps_extremes_in_order() -> None:
    t = np.linspace(0.0, 100.0, 100_001)
    y = np.sin(7.0 * t) + 1e-3 * t
    tt, yy = envelope(t, y, points=1000)
    assert tt.size <= 2000 + 2 and np.all(np.diff(tt) >= 0)
    assert yy.max() == y.max() and yy.min() == y.min()
    small_t, small_y = envelope(t[:50], y[:50], points=1000)
    assert np.array_equal(small_t, t[:50]) and np.array_equal(small_y, y[:50])


def test_every_axis_carries_the_unit_stored_with_the_results(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from cosim.runner import run_scenario

    scenario = load(ROOT / "scenarios" / "oscillator.toml")
    files = [run_scenario(scenario, stop=0.2, output=tmp_path / f"osc{s}", inprocess=True, progress=False).output
             for s in (".csv", ".npz")]
    labels: dict[str, list[str]] = {}
    real_figure = cosim_plot.figure

    def spy(results, series, title, ylabels, path, wrap=None):
        labels[title] = list(ylabels)
        return real_figure(results, series, title, ylabels, path, wrap)

    monkeypatch.setattr(cosim_plot, "figure", spy)
    for f in files:
        labels.clear()
        plot_files([f], tmp_path / "png")
        assert labels == {"mass1.u": ["mass1.u[0] (m)"], "mass1.v": ["mass1.v[0] (m/s)"],
                          "mass2.u": ["mass2.u[0] (m)"], "mass2.v": ["mass2.v[0] (m/s)"]}, f
    labels.clear()
    plot_files([generic_result(tmp_path / "old.csv")], tmp_path / "png")  # no units stored: none invented
    assert labels["m1.u"] == ["m1.u[0]"]


def test_a_png_appears_whole_or_not_at_all(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import matplotlib.figure

    def dies_halfway(self, f, **kw) -> None:
        f.write(b"\x89PNG half")
        raise RuntimeError("renderer died")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", dies_halfway)
    with pytest.raises(RuntimeError, match="renderer died"):
        plot_files([generic_result(tmp_path / "a.csv")], tmp_path / "png")
    assert list((tmp_path / "png").iterdir()) == []


def test_a_diagnostics_file_given_alone_is_plotted(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                   drawn: dict[str, dict]) -> None:
    """It was refused as 'belonging to a result file' (exit 2): the stages, lengths and error estimates of an
    automatic interval's run could not be seen (newcomer probe)."""
    diag = tmp_path / "a.csv.diag.csv"
    diag.write_text("interval,t0,t1,stages,largest_residual,wall_time_s,halvings,restarts,length_s,error\n"
                    "1,0.0,0.4,3,1e-12,0.01,0,0,0.4,0.25\n2,0.4,1.2,2,2e-12,0.02,1,0,0.8,0.5\n")
    assert cosim_main(["plot", str(diag), "--out", str(tmp_path / "png")]) == 0
    (printed,) = capsys.readouterr().out.split()
    assert Path(printed).name == "diagnostics.png"
    assert_real_png(Path(printed))
    shown = drawn["diagnostics.png"]
    assert shown["ylabels"] == ["stages", "interval length (s)", "error / interval_tol", "tries rolled back",
                                "largest residual", "wall time (s)"]
    (label, t, stages), = shown["lines"][0]
    assert label == "a.csv.diag.csv" and list(t) == [0.4, 1.2] and list(stages) == [3.0, 2.0]
    assert list(shown["lines"][2][0][2]) == [0.25, 0.5]
    assert list(shown["lines"][3][0][2]) == [0.0, 1.0]  # the second interval's rolled-back try
    (tmp_path / "x.diag.csv").write_text("not,a\ndiagnostics,file\n")
    assert cosim_main(["plot", str(tmp_path / "x.diag.csv"), "--out", str(tmp_path / "png")]) == 2
    assert "is not a diagnostics file cosim wrote" in capsys.readouterr().err
