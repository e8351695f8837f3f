"""Every python block of docs/api.md runs, in order, in one namespace, from the repository root."""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).parents[1]


def test_the_api_page_runs() -> None:
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "api.md").read_text(), re.S)
    assert len(blocks) == 5
    namespace: dict = {}
    cwd = os.getcwd()
    os.chdir(ROOT)  # the examples name scenarios relative to the repository
    try:
        for i, block in enumerate(blocks):
            exec(compile(block, f"docs/api.md block {i + 1}", "exec"), namespace)
    finally:
        os.chdir(cwd)
    # what the comments promise
    assert namespace["r"].t.shape == (17,)  # the loop's last run: stop 0.2, 4 intervals
    np.testing.assert_allclose(namespace["res"].outputs["y"][-1], [1.4, -1.6], rtol=1e-15)  # y0 + 0.4 u
    assert namespace["summary"].intervals == 10
    assert namespace["action"].summary.intervals == 2
    assert abs(namespace["y0"] - math.exp(-1.0)) < 2e-3 and namespace["y0"] != np.exp(-1.0)
