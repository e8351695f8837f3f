"""The README's subsim example runs as written."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from cosim.contract import SubsimError
from cosim.handles import InProcessHandle


def test_readme_thermal_example_matches_closed_form() -> None:
    text = (Path(__file__).parents[1] / "README.md").read_text()
    block = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    namespace: dict = {}
    exec(compile(block, "README.md", "exec"), namespace)
    h = InProcessHandle(namespace["Thermal"]())
    h.configure({"C": 100.0, "G": 2.0, "T0": 300.0, "T_env": 290.0})
    t = np.linspace(0.0, 10.0, 101)
    T = h.run_interval(t, {"P_in": np.full((t.size, 1), 40.0)}).outputs["T"][:, 0]
    # C T' = P - G (T - T_env): T -> T_env + P/G = 310 with time constant C/G = 50 s
    exact = 310.0 + (300.0 - 310.0) * np.exp(-t / 50.0)
    np.testing.assert_allclose(T, exact, atol=1e-4)


def test_readme_points_to_pages_that_exist_and_names_real_signals() -> None:
    root = Path(__file__).parents[1]
    text = (root / "README.md").read_text()
    links = re.findall(r"\]\((docs/[\w.]+\.md)\)", text)
    assert {"docs/tutorial.md", "docs/scenarios.md", "docs/api.md", "docs/protocol.md",
            "docs/architecture.md"} <= set(links)
    assert all((root / link).is_file() for link in links)
    call = re.search(r'cosim\.run\("([^"]+)".*\n.*r\["(\w+)\.(\w+)"\]', text)
    from cosim.scenario import load

    spec = load(root / call.group(1)).subsims[call.group(2)]
    assert call.group(3) in spec.model_class().outputs


def test_readme_thermal_declares_its_parameters() -> None:
    block = re.search(r"```python\n(.*?)```", (Path(__file__).parents[1] / "README.md").read_text(), re.S).group(1)
    namespace: dict = {}
    exec(compile(block, "README.md", "exec"), namespace)
    h = InProcessHandle(namespace["Thermal"]())
    assert h.configure({}).params["C"].unit == "J/K"
    with pytest.raises(SubsimError, match="did you mean 'T0'"):
        h.configure({"T_0": 300.0})
