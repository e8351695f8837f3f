"""Build the mass FMUs from C with gcc against FMPy's FMI headers (no downloads).

    python scenarios/fmu/build_mass.py          # mass2.fmu (FMI 2.0) and mass3.fmu (FMI 3.0) beside this file

``build_mass_fmu(dir, version=2|3, state=True)`` gives ``mass.fmu``: one mass on a spring to ground
driven by a force input (``csrc/mass_core.h``), co-simulation and model exchange in one binary.
FMPy binds every FMI function of the standard when it loads a binary, so the functions this
model does not implement are generated as stubs that return ``fmiError``.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import zipfile
from pathlib import Path

import fmpy

CSRC = Path(__file__).parent / "csrc"
HEADERS = Path(fmpy.__file__).parent / "c-code"
PLATFORM = {2: fmpy.platform, 3: fmpy.platform_tuple}
ERROR = {2: 3, 3: 3}  # fmi2Error, fmi3Error

# name, causality, variability, initial, unit, start, description
VARIABLES = [
    ("u", "output", "continuous", "calculated", "m", None, "displacement"),
    ("v", "output", "continuous", "calculated", "m/s", None, "velocity"),
    ("F", "input", "continuous", None, "N", "0", "external force on the mass"),
    ("m", "parameter", "fixed", "exact", "kg", "1", "mass"),
    ("k", "parameter", "fixed", "exact", "N/m", "39.47841760435743", "spring to ground"),
    ("u0", "parameter", "fixed", "exact", "m", "0", "initial displacement"),
    ("v0", "parameter", "fixed", "exact", "m/s", "0", "initial velocity"),
    ("der(u)", "local", "continuous", "calculated", "m/s", None, ""),
    ("der(v)", "local", "continuous", "calculated", "m/s2", None, ""),
]
UNITS = ["m", "m/s", "m/s2", "N", "kg", "N/m"]


def _attrs(**kw: object) -> str:
    return " ".join(f'{k}="{v}"' for k, v in kw.items() if v is not None)


def model_description(version: int, state: bool = True, identifier: str = "mass", float32: bool = False) -> str:
    """``float32`` (FMI 3 only): v and F are Float32 variables (the binary must be built with it too)."""
    flag = "true" if state else "false"
    units = "".join(f'<Unit name="{u}"/>' for u in UNITS)
    if version == 2:
        caps = f'canGetAndSetFMUstate="{flag}" canSerializeFMUstate="{flag}"'
        rows = []
        for i, (name, caus, var, init, unit, start, doc) in enumerate(VARIABLES):
            deriv = {"der(u)": 1, "der(v)": 2}.get(name)
            real = f"<Real {_attrs(unit=unit, start=start, derivative=deriv)}/>"
            head = _attrs(name=name, valueReference=i, causality=caus, variability=var, initial=init,
                          description=doc or None)
            rows.append(f"<ScalarVariable {head}>{real}</ScalarVariable>")
        structure = ('<Outputs><Unknown index="1"/><Unknown index="2"/></Outputs>'
                     '<Derivatives><Unknown index="8"/><Unknown index="9"/></Derivatives>'
                     '<InitialUnknowns><Unknown index="1"/><Unknown index="2"/><Unknown index="8"/>'
                     '<Unknown index="9"/></InitialUnknowns>')
        return (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="2.0" modelName="Mass" '
                f'guid="{{cosim-test-mass-2}}" numberOfEventIndicators="0" description="one mass, spring to ground">'
                f'<ModelExchange modelIdentifier="{identifier}" {caps}/>'
                f'<CoSimulation modelIdentifier="{identifier}" canHandleVariableCommunicationStepSize="true" {caps}/>'
                f'<UnitDefinitions>{units}</UnitDefinitions>'
                f'<DefaultExperiment startTime="0" stopTime="1" stepSize="0.01"/>'
                f'<ModelVariables>{"".join(rows)}</ModelVariables><ModelStructure>{structure}</ModelStructure>'
                f'</fmiModelDescription>\n')
    caps = f'canGetAndSetFMUState="{flag}" canSerializeFMUState="{flag}"'
    rows = ['<Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>']
    for i, (name, caus, var, init, unit, start, doc) in enumerate(VARIABLES):
        deriv = {"der(u)": 1, "der(v)": 2}.get(name)
        attrs = _attrs(name=name, valueReference=i + 1, causality=caus, variability=var, initial=init, unit=unit,
                       start=start, derivative=deriv, description=doc or None)
        kind = "Float32" if float32 and name in {"v", "F"} else "Float64"
        rows.append(f"<{kind} {attrs}/>")
    structure = ('<Output valueReference="1"/><Output valueReference="2"/>'
                 '<ContinuousStateDerivative valueReference="8"/><ContinuousStateDerivative valueReference="9"/>'
                 '<InitialUnknown valueReference="1"/><InitialUnknown valueReference="2"/>'
                 '<InitialUnknown valueReference="8"/><InitialUnknown valueReference="9"/>')
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="3.0" modelName="Mass" '
            f'instantiationToken="{{cosim-test-mass-3}}" description="one mass, spring to ground">'
            f'<ModelExchange modelIdentifier="{identifier}" {caps}/>'
            f'<CoSimulation modelIdentifier="{identifier}" canHandleVariableCommunicationStepSize="true" {caps}/>'
            f'<UnitDefinitions>{units}</UnitDefinitions>'
            f'<DefaultExperiment startTime="0" stopTime="1" stepSize="0.01"/>'
            f'<ModelVariables>{"".join(rows)}</ModelVariables><ModelStructure>{structure}</ModelStructure>'
            f'</fmiModelDescription>\n')


def _standard_functions(version: int) -> list[str]:
    header = (HEADERS / f"fmi{version}Functions.h").read_text()
    return sorted(set(re.findall(rf"#define\s+(fmi{version}\w+)\s+fmi{version}FullName\(", header)))


def _run(cmd: list[str]) -> str:
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{done.stderr}")
    return done.stdout


def compile_binary(work: Path, version: int, state: bool = True, identifier: str = "mass",
                   float32: bool = False, step_event_at: float | None = None, warn_at: float | None = None,
                   discard_above: float | None = None) -> Path:
    """``<identifier>.so`` of the mass model for FMI ``version`` (``float32``: see :func:`model_description`;
    ``step_event_at``, FMI 2: model exchange asks for event mode at the first integrator step from then on;
    ``warn_at``: every co-simulation step from then on logs a warning and returns the Warning status;
    ``discard_above``: a co-simulation step longer than this is discarded, nothing stepped)."""
    work.mkdir(parents=True, exist_ok=True)
    obj = work / f"mass_fmi{version}.o"
    flags = ["-O2", "-fPIC", "-Wall", "-Werror", f"-I{HEADERS}", f"-I{CSRC}", f"-DMASS_STATE={int(state)}",
             f"-DMASS_F32={int(float32)}", f"-DMASS_STEP_EVENT_AT={-1.0 if step_event_at is None else step_event_at!r}",
             f"-DMASS_WARN_AT={-1.0 if warn_at is None else warn_at!r}",
             f"-DMASS_DISCARD_ABOVE={0.0 if discard_above is None else discard_above!r}"]
    _run(["gcc", *flags, "-c", str(CSRC / f"mass_fmi{version}.c"), "-o", str(obj)])
    defined = set(_run(["nm", "-g", "--defined-only", str(obj)]).split())
    stubs = [f for f in _standard_functions(version) if f not in defined]
    stub_c = work / f"stubs_fmi{version}.c"
    stub_c.write_text("/* generated: FMI functions this test model does not implement */\n"
                      + "".join(f"int {f}(void) {{ return {ERROR[version]}; }}\n" for f in stubs))
    so = work / f"{identifier}.so"
    _run(["gcc", "-shared", "-fPIC", "-O2", str(obj), str(stub_c), "-o", str(so), "-lm"])
    return so


def write_fmu(path: Path, xml: str | None, binaries: dict[str, Path], extra: dict[str, bytes] | None = None) -> Path:
    """Zip an FMU: ``modelDescription.xml`` (unless None), ``binaries/<platform>/<file>`` and extra members."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        if xml is not None:
            zf.writestr("modelDescription.xml", xml)
        for platform, so in binaries.items():
            zf.write(so, f"binaries/{platform}/{so.name}")
        for name, data in (extra or {}).items():
            zf.writestr(name, data)
    return path


def build_mass_fmu(out: Path, version: int = 2, state: bool = True, name: str | None = None,
                   float32: bool = False, step_event_at: float | None = None, warn_at: float | None = None,
                   discard_above: float | None = None) -> Path:
    """Compile and package the mass FMU; returns the path of the ``.fmu`` (options: :func:`compile_binary`)."""
    name = name or f"mass{version}{'' if state else '_nostate'}{'_f32' if float32 else ''}"
    so = compile_binary(out / f"build-{name}", version, state, float32=float32, step_event_at=step_event_at,
                        warn_at=warn_at, discard_above=discard_above)
    return write_fmu(out / f"{name}.fmu", model_description(version, state, float32=float32), {PLATFORM[version]: so})


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description="Build mass2.fmu and mass3.fmu (needs gcc and fmpy).")
    p.add_argument("--out", type=Path, default=Path(__file__).parent, help="directory for the FMUs")
    args = p.parse_args(argv)
    for version in (2, 3):
        print(build_mass_fmu(args.out, version))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
