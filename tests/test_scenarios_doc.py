"""docs/scenarios.md documents every key of cosim.scenario.KEYS and no other.

The key tables between the ``<!-- keys -->`` markers are generated: on a mismatch the assertion shows
the text to paste (``python tests/test_scenarios_doc.py`` prints it, ``... --write`` puts it in the page).
"""

from __future__ import annotations

import re
from pathlib import Path

from cosim.scenario import KEYS, Key, load

DOC = Path(__file__).parents[1] / "docs" / "scenarios.md"
MARKED = re.compile(r"<!-- keys -->\n(.*?)<!-- /keys -->", re.S)


def heading(table: str) -> str:
    if table == "":
        return "Top level (before any table)"
    if table.endswith("[]"):
        return f"`[[{table[:-2]}]]` (any number of them)"
    return f"`[{table}]`"


def row(name: str, k: Key) -> str:
    cells = [f"`{name}`", k.type, k.default.replace("|", "\\|"), k.unit or "–", k.meaning.replace("|", "\\|")]
    return "| " + " | ".join(cells) + " |"


def render() -> str:
    out = []
    for table, keys in KEYS.items():
        out.append(f"### {heading(table)}\n")
        if table == "coupling.<method>":
            assert keys == {k: v for k, v in KEYS["coupling"].items() if k != "method"}
            out.append("The keys of `[coupling]` but `method`, for one method only: `[coupling.centralized]`, "
                       "`[coupling.distributed]`. They override `[coupling]` for that method.\n")
            continue
        out.append("| key | type | default | unit | meaning |\n|---|---|---|---|---|")
        out.extend(row(name, k) for name, k in keys.items())
        out.append("")
    return "\n".join(out)


def test_the_key_tables_are_generated_from_keys() -> None:
    found = MARKED.search(DOC.read_text())
    assert found, "docs/scenarios.md lost its <!-- keys --> ... <!-- /keys --> markers"
    assert found.group(1) == render(), f"regenerate the key tables of docs/scenarios.md:\n\n{render()}"


def pattern(table: str) -> str | None:
    """The KEYS table a TOML header stands for; None for tables of free keys (a model's params ...)."""
    parts = re.findall(r'"[^"]*"|[^.]+', table)
    if parts[0] == "subsims":
        return "subsims.<name>" if len(parts) == 2 else None
    if parts[0] == "tolerances":
        return "tolerances.<signal>"
    if parts[0] == "coupling" and len(parts) == 2:
        return "coupling.<method>"
    if parts[0] == "unified" and len(parts) == 2:
        return None
    return {"couplings": "couplings[]"}.get(table, table)


def test_the_toml_examples_use_only_keys_the_loader_knows(tmp_path: Path) -> None:
    examples = re.findall(r"```toml\n(.*?)```", MARKED.sub("", DOC.read_text()), re.S)
    assert len(examples) >= 2
    for block in examples:
        table: str | None = ""
        for line in block.splitlines():
            line = line.split("#")[0].strip()
            header = re.fullmatch(r"\[\[?([^\]]+)\]\]?", line)
            if header:
                table = pattern(header.group(1))
                assert table is None or table in KEYS, f"[{header.group(1)}] is not a scenario table"
            elif "=" in line and table is not None:
                key = line.split("=")[0].strip()
                assert key in KEYS[table], f"[{table}] {key} is not a scenario key"
    example = tmp_path / "example.toml"  # the first example is a whole scenario: the loader takes it
    example.write_text(examples[0])
    assert [str(c) for c in load(example).couplings] == ["mass2.u -> mass1.F", "mass1.u -> mass2.F"]


if __name__ == "__main__":  # python tests/test_scenarios_doc.py [--write]
    import sys

    if sys.argv[1:] == ["--write"]:
        text = DOC.read_text()
        found = MARKED.search(text)
        assert found, "docs/scenarios.md lost its <!-- keys --> ... <!-- /keys --> markers"
        DOC.write_text(text[:found.start(1)] + render() + text[found.end(1):])
        print(f"regenerated the key tables of {DOC}")
    else:
        print(render())
