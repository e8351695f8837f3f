"""``python -m subsims.lagrange_pair.plots``: every figure from a real (short) coupled run, and bad input."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("matplotlib")

from cosim.runner import run_scenario  # noqa: E402
from cosim.scenario import load  # noqa: E402
from subsims.lagrange_pair import plots  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
FIGURES = ("trajectory", "attitude", "joint_force", "loads", "coupled_vs_builtin")


def test_every_figure_is_written(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    scenario = load(ROOT / "scenarios" / "lagrange_pair" / "pair_aero.toml")
    report = run_scenario(scenario, stop=1.0, output=tmp_path / "pair.csv", inprocess=True, progress=False,
                          log=lambda m: None)
    assert plots.main([str(report.output), "--out", str(tmp_path / "png"), "--reference"]) == 0
    printed = sorted(Path(p).name for p in capsys.readouterr().out.split())
    assert printed == sorted(f"{name}.png" for name in FIGURES)
    for name in FIGURES:
        png = tmp_path / "png" / f"{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000, png


def test_a_file_without_the_pair_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    other = tmp_path / "other.csv"
    other.write_text("time,m.x[0]\n0,1\n1,2\n")
    assert plots.main([str(other), "--out", str(tmp_path / "png")]) == 2
    assert "not a lagrange_pair result" in capsys.readouterr().err
