"""Test FMUs, built once per session from C (scenarios/fmu/csrc) with gcc against FMPy's FMI headers."""

from __future__ import annotations

import importlib.util
import shutil
import zipfile
from pathlib import Path

import pytest

pytest.importorskip("fmpy", reason="FMU support needs the fmi extra (fmpy)")

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("build_mass", ROOT / "scenarios" / "fmu" / "build_mass.py")
build_mass = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(build_mass)

K12 = 16 * 3.141592653589793**2  # the middle spring
K = 20 * 3.141592653589793**2  # each mass's own spring plus the middle one


def _needs_gcc() -> None:
    if shutil.which("gcc") is None or shutil.which("nm") is None:
        pytest.skip("building the test FMUs needs gcc and nm")


@pytest.fixture(scope="session")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``mass2``, ``mass3`` (FMI 2.0 / 3.0, CS + ME, state serialization), ``mass2_nostate``,
    ``mass3_nostate`` (cannot save state), and broken ones: ``not_zip``, ``no_description``,
    ``no_binary``, ``other_platform``, ``bad_description``."""
    _needs_gcc()
    out = tmp_path_factory.mktemp("fmus")
    built = {f"mass{v}": build_mass.build_mass_fmu(out, v) for v in (2, 3)}
    built.update({f"mass{v}_nostate": build_mass.build_mass_fmu(out, v, state=False) for v in (2, 3)})
    so = out / "build-mass2" / "mass.so"
    xml = build_mass.model_description(2)
    (out / "not_zip.fmu").write_bytes(b"this is not a zip archive\n" * 10)
    built["not_zip"] = out / "not_zip.fmu"
    built["no_description"] = build_mass.write_fmu(out / "no_description.fmu", None, {build_mass.PLATFORM[2]: so})
    built["no_binary"] = build_mass.write_fmu(out / "no_binary.fmu", xml, {})
    built["other_platform"] = build_mass.write_fmu(out / "other_platform.fmu", xml, {"win64": so})
    built["bad_description"] = build_mass.write_fmu(out / "bad_description.fmu", "<fmiModelDescription",
                                                    {build_mass.PLATFORM[2]: so})
    for path in built.values():
        assert path.is_file()
    with zipfile.ZipFile(built["mass3"]) as zf:
        assert f"binaries/{build_mass.PLATFORM[3]}/mass.so" in zf.namelist()
    return built
