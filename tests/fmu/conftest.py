"""Test FMUs, built once per session from C (scenarios/fmu/csrc) with gcc against FMPy's FMI headers."""

from __future__ import annotations

import importlib.util
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy", reason="FMU support needs the fmi extra (fmpy)")

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("build_mass", ROOT / "scenarios" / "fmu" / "build_mass.py")
build_mass = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(build_mass)


def _needs_gcc() -> None:
    if shutil.which("gcc") is None or shutil.which("nm") is None:
        pytest.skip("building the test FMUs needs gcc and nm")


@pytest.fixture(scope="session")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``mass2``, ``mass3`` (FMI 2.0 / 3.0, CS + ME, state serialization), ``mass2_warn``, ``mass3_warn`` (every
    step from t = 0.25 logs a warning), ``mass2_discard``, ``mass3_discard`` (a step longer than 0.02 s is
    discarded), ``mass2_alias`` (x0 is u0), ``mass3_extras`` (variables cosim does not use,
    and sized integer and Float32 parameters), ``misnamed_binary``, ``mass2_nostate``,
    ``mass3_nostate`` (cannot save state), ``mass3_f32`` (v and F are Float32), ``mass2_step_event`` (model
    exchange asks for event mode at its first integrator step from t = 0.25), and broken ones:
    ``not_zip``, ``no_description``, ``no_binary``, ``other_platform``, ``bad_binary`` (it cannot load),
    ``bad_description``."""
    _needs_gcc()
    out = tmp_path_factory.mktemp("fmus")
    built = {f"mass{v}": build_mass.build_mass_fmu(out, v) for v in (2, 3)}
    built.update({f"mass{v}_nostate": build_mass.build_mass_fmu(out, v, state=False) for v in (2, 3)})
    built["mass3_f32"] = build_mass.build_mass_fmu(out, 3, float32=True)
    built["mass2_step_event"] = build_mass.build_mass_fmu(out, 2, name="mass2_step_event", step_event_at=0.25)
    built.update({f"mass{v}_warn": build_mass.build_mass_fmu(out, v, name=f"mass{v}_warn", warn_at=0.25)
                  for v in (2, 3)})
    built.update({f"mass{v}_discard": build_mass.build_mass_fmu(out, v, name=f"mass{v}_discard", discard_above=0.02)
                  for v in (2, 3)})
    so = out / "build-mass2" / "mass.so"
    xml = build_mass.model_description(2)
    # an alias of u0 (FMI 2: another variable of the same value reference and type)
    alias = ('<ScalarVariable name="x0" valueReference="5" causality="parameter" variability="fixed" '
             'initial="exact"><Real unit="m" start="0"/></ScalarVariable>')
    built["mass2_alias"] = build_mass.write_fmu(out / "mass2_alias.fmu",
                                                xml.replace("</ModelVariables>", alias + "</ModelVariables>"),
                                                {build_mass.PLATFORM[2]: so})
    # FMI 3 variables cosim neither couples nor sets: an array parameter, an array input, an Int32 output (and an Int32
    # input, set as a value, not coupled)
    extras = ('<Float64 name="gains" valueReference="20" causality="parameter" variability="fixed" start="1 2">'
              '<Dimension start="2"/></Float64>'
              '<Float64 name="bias" valueReference="21" causality="input" variability="continuous" start="0 0">'
              '<Dimension start="2"/></Float64>'
              '<Int32 name="count" valueReference="22" causality="output" variability="discrete"/>'
              '<Int32 name="mode" valueReference="23" causality="parameter" variability="fixed" start="0"/>'
              '<Int32 name="gear" valueReference="27" causality="input" variability="discrete" start="1"/>'
              '<UInt64 name="rows" valueReference="26" causality="structuralParameter" variability="fixed" '
              'start="2"/>'
              '<UInt8 name="level" valueReference="24" causality="parameter" variability="fixed" start="0"/>'
              '<Float32 name="gain32" valueReference="25" causality="parameter" variability="fixed" start="1"/>')
    xml3 = build_mass.model_description(3).replace("</ModelVariables>", extras + "</ModelVariables>")
    xml3 = xml3.replace('<Output valueReference="2"/>', '<Output valueReference="2"/><Output valueReference="22"/>')
    built["mass3_extras"] = build_mass.write_fmu(out / "mass3_extras.fmu", xml3,
                                                 {build_mass.PLATFORM[3]: out / "build-mass3" / "mass.so"})
    misnamed = out / "misnamed" / "Mass_Model.so"
    misnamed.parent.mkdir()
    shutil.copy(so, misnamed)
    built["misnamed_binary"] = build_mass.write_fmu(out / "misnamed_binary.fmu", xml,
                                                    {build_mass.PLATFORM[2]: misnamed})
    (out / "not_zip.fmu").write_bytes(b"this is not a zip archive\n" * 10)
    built["not_zip"] = out / "not_zip.fmu"
    built["no_description"] = build_mass.write_fmu(out / "no_description.fmu", None, {build_mass.PLATFORM[2]: so})
    built["no_binary"] = build_mass.write_fmu(out / "no_binary.fmu", xml, {})
    built["other_platform"] = build_mass.write_fmu(out / "other_platform.fmu", xml, {"win64": so})
    junk = out / "junk" / "mass.so"
    junk.parent.mkdir()
    junk.write_bytes(b"\x7fELF" + b"\x00" * 60)  # an ELF header and nothing a loader can use
    built["bad_binary"] = build_mass.write_fmu(out / "bad_binary.fmu", xml, {build_mass.PLATFORM[2]: junk})
    built["bad_description"] = build_mass.write_fmu(out / "bad_description.fmu", "<fmiModelDescription",
                                                    {build_mass.PLATFORM[2]: so})
    for path in built.values():
        assert path.is_file()
    with zipfile.ZipFile(built["mass3"]) as zf:
        assert f"binaries/{build_mass.PLATFORM[3]}/mass.so" in zf.namelist()
    return built


def two_masses(path: Path, times: np.ndarray, k: float, k12: float, u0: tuple[float, float]) -> np.ndarray:
    """One-process reference: the two mass FMUs stepped together by FMPy alone (not the code under test),
    with the given communication points; at every point each FMU's force is k12 times the other's
    displacement there, held over the step (a Jacobi co-simulation master). Columns u1, v1, u2, v2."""
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave
    from fmpy.model_description import read_model_description

    md = read_model_description(str(path))
    unzip = fmpy.extract(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    v3 = md.fmiVersion.startswith("3")
    fmus = []
    for i in range(2):
        fmu = (FMU3Slave if v3 else FMU2Slave)(guid=md.guid, unzipDirectory=unzip,
                                               modelIdentifier=md.coSimulation.modelIdentifier, instanceName=f"r{i}")
        fmu.instantiate()
        set_real, get_real = (fmu.setFloat64, fmu.getFloat64) if v3 else (fmu.setReal, fmu.getReal)
        if not v3:
            fmu.setupExperiment(startTime=float(times[0]))
        set_real([vr["m"], vr["k"], vr["u0"]], [1.0, k, u0[i]])
        if v3:
            fmu.enterInitializationMode(startTime=float(times[0]))
        else:
            fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmus.append((fmu, set_real, get_real))
    (f1, set1, get1), (f2, set2, get2) = fmus
    out = np.empty((times.size, 4))
    try:
        for j, t in enumerate(times):
            u1, v1 = get1([vr["u"], vr["v"]])
            u2, v2 = get2([vr["u"], vr["v"]])
            out[j] = u1, v1, u2, v2
            if j + 1 < times.size:
                set1([vr["F"]], [k12 * u2])
                set2([vr["F"]], [k12 * u1])
                h = float(times[j + 1] - t)
                f1.doStep(float(t), h)
                f2.doStep(float(t), h)
    finally:
        for fmu, _, _ in fmus:
            fmu.terminate()
            fmu.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)
    return out


@pytest.fixture(scope="session")
def two_mass_reference():
    """The one-process reference :func:`two_masses`."""
    return two_masses
