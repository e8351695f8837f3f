"""docs/architecture.md lists the layers exactly as the import contract that CI checks orders them."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).parents[1]


def contract_layers() -> list[str]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    (layers,) = [c["layers"] for c in config["contracts"] if c["type"] == "layers"]
    return layers


def documented_layers() -> list[str]:
    text = (ROOT / "docs" / "architecture.md").read_text()
    block = re.search(r"<!-- layers -->\n```\n(.*?)```\n<!-- /layers -->", text, re.S)
    assert block, "docs/architecture.md lost its <!-- layers --> ... <!-- /layers --> block"
    # each line: the layer's modules (joined by ' | ' or ' : '), then two or more spaces and a comment
    return [re.split(r"\s{2,}", line.strip())[0] for line in block.group(1).splitlines() if line.strip()]


def test_the_documented_layers_are_the_contracts() -> None:
    assert documented_layers() == contract_layers()
