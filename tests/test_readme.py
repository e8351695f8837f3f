"""The README's subsim example runs as written."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

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
