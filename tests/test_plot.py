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
def test_satellite_figures(satellite_results: list[Path], tmp_path: Path) -> None:
    diag = [p.with_name(p.stem + ".diag.csv") for p in satellite_results]  # as a shell glob would add them
    args = argparse.Namespace(results=[*satellite_results, *diag], out=tmp_path / "png", signals=None)
    assert plot_command(args) == 0
    for name in ("satellite-euler", "satellite-rates", "satellite-altitude", "orbit.R", "orbit.V",
                 "attitude.phi", "attitude.omega", "aero.force", "aero.torque"):
        assert_real_png(tmp_path / "png" / f"{name}.png")


def test_time_window(satellite_results: list[Path], tmp_path: Path) -> None:
    written = plot_files(satellite_results, tmp_path, window=(20.0, 40.0))
    assert tmp_path / "satellite-euler.png" in written
    with pytest.raises(PlotError, match="inside the window"):
        plot_files(satellite_results, tmp_path, window=(100.0, 200.0))


def test_generic_signals_via_cli(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    a, b = generic_result(tmp_path / "a.csv"), generic_result(tmp_path / "b.csv", shift=0.5)
    assert cosim_main(["plot", str(a), str(b), "--out", str(tmp_path / "png")]) == 0
    printed = capsys.readouterr().out.split()
    assert sorted(Path(p).name for p in printed) == ["m1.u.png", "m1.v.png", "m2.x.png"]
    for p in printed:
        assert_real_png(Path(p))
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
