"""Units in an SSP import: a parameter value given in a unit reaches its FMU variable in the variable's unit,
and a connection between ports in two units of one quantity converts (SSP does, where cosim's own check
refuses an identity coupling between two units). Expected values are worked out by hand from the unit
definitions below (value_SI = value * factor + offset)."""

from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from cosim.scenario import ScenarioError, load
from subsims.fmu.ssp import read_ssp

pytestmark = [pytest.mark.slow]  # builds the test FMUs

SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
SSM = "http://ssp-standard.org/SSP1/SystemStructureParameterMapping"
COMPANION = "[coupling]\ninterval = 0.05\nsamples = 3\n"
# the mass FMU's units, each with its SI definition (the built FMU names them without one)
DEFINED = ('<Unit name="m"><BaseUnit m="1"/></Unit><Unit name="m/s"><BaseUnit m="1" s="-1"/></Unit>'
           '<Unit name="m/s2"><BaseUnit m="1" s="-2"/></Unit><Unit name="N"><BaseUnit kg="1" m="1" s="-2"/></Unit>'
           '<Unit name="kg"><BaseUnit kg="1"/></Unit><Unit name="N/m"><BaseUnit kg="1" s="-2"/></Unit>'
           '<Unit name="mm"><BaseUnit m="1" factor="0.001"/></Unit>'
           '<Unit name="degC"><BaseUnit K="1" offset="273.15"/></Unit><Unit name="K"><BaseUnit K="1"/></Unit>')


def variant(fmus: dict[str, Path], out: Path, *, defined: bool = True, u: str = "m", force: str = "N") -> Path:
    """The built FMI 2 mass FMU (its binary unchanged) with its description edited: its units defined in SI
    (``defined``), the output u in ``u`` and the input F in ``force``."""
    with zipfile.ZipFile(fmus["mass2"]) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    xml = members["modelDescription.xml"].decode()
    if defined:
        start, end = xml.index("<UnitDefinitions>") + len("<UnitDefinitions>"), xml.index("</UnitDefinitions>")
        xml = xml[:start] + DEFINED + xml[end:]
    for name, unit in (("u", u), ("F", force)):
        head = xml.index(f'<ScalarVariable name="{name}"')
        real = xml.index("<Real ", head)
        old = xml[real:xml.index("/>", real)]
        assert 'unit="' in old
        xml = xml[:real] + old.replace(old[old.index('unit="'):old.index('"', old.index('unit="') + 6) + 1],
                                       f'unit="{unit}"') + xml[real + len(old):]
    members["modelDescription.xml"] = xml.encode()
    with zipfile.ZipFile(out, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return out


def parameters(rows: dict[str, tuple[float, str | None]], units: str = "") -> str:
    body = "".join(f'<ssv:Parameter name="{n}"><ssv:Real value="{v!r}"{f" unit={u!r}" if u else ""}/>'
                   "</ssv:Parameter>" for n, (v, u) in rows.items())
    units = f'<ssv:Units><ssc:Unit xmlns:ssc="{SSC}" name="g"><ssc:BaseUnit kg="1" factor="0.001"/></ssc:Unit>' \
            f"{units}</ssv:Units>"
    return (f'<ssv:ParameterSet xmlns:ssv="{SSV}" version="1.0" name="p"><ssv:Parameters>{body}</ssv:Parameters>'
            f"{units}</ssv:ParameterSet>")


def component(name: str, bindings: str = "", connectors: str = "") -> str:
    return (f'<ssd:Component name="{name}" type="application/x-fmu-sharedlibrary" source="resources/{name}.fmu">'
            f"<ssd:Connectors>{connectors}</ssd:Connectors>"
            f"<ssd:ParameterBindings>{bindings}</ssd:ParameterBindings></ssd:Component>")


def connection(inner: str = "", suppress: bool = False) -> str:
    flag = ' suppressUnitConversion="true"' if suppress else ""
    return (f'<ssd:Connection startElement="a" startConnector="u" endElement="b" endConnector="F"{flag}>{inner}'
            "</ssd:Connection>")


def write(tmp_path: Path, fmus: dict[str, Path], components: str, connections: str = "",
          ssd_units: str = "", files: dict[str, str] | None = None, system_bindings: str = "") -> Path:
    """``system.ssp`` with components a and b (``fmus``: name -> FMU file) and a companion TOML;
    ``system_bindings``: ParameterBinding elements of the system."""
    ssd = (f'<?xml version="1.0" encoding="UTF-8"?>\n<ssd:SystemStructureDescription xmlns:ssd="{SSD}" '
           f'xmlns:ssc="{SSC}" xmlns:ssv="{SSV}" version="1.0" name="units"><ssd:System name="top">'
           f"<ssd:ParameterBindings>{system_bindings}</ssd:ParameterBindings><ssd:Elements>{components}</ssd:Elements><ssd:Connections>{connections}</ssd:Connections></ssd:System>"
           f"<ssd:Units>{ssd_units}</ssd:Units>"
           '<ssd:DefaultExperiment startTime="0" stopTime="0.1"/></ssd:SystemStructureDescription>')
    path = tmp_path / "system.ssp"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("SystemStructure.ssd", ssd)
        for name, fmu in fmus.items():
            zf.write(fmu, f"resources/{name}.fmu")
        for name, text in (files or {}).items():
            zf.writestr(name, text)
    (tmp_path / "system.toml").write_text(COMPANION)
    return path


def params(raw: dict, name: str) -> dict:
    return {k: v for k, v in raw["subsims"][name]["params"].items() if k != "fmu"}


def test_a_parameter_value_with_a_unit_reaches_the_fmu_in_the_variables_unit(
    tmp_path: Path, fmus: dict[str, Path]
) -> None:
    """m = 1000 g in an .ssv bound on the system (g defined there) is 1.0 kg (the FMU got m = 1000 kg); u0 = 5 cm
    inline (cm defined in the SSD's Units) is 0.05 m; a value in the variable's own unit passes as it is; one
    without a unit too."""
    fmu = variant(fmus, tmp_path / "a.fmu")
    ssv = parameters({"a.m": (1000.0, "g"), "a.k": (40.0, "N/m"), "a.v0": (2.0, None)})
    inline = ("<ssd:ParameterBinding><ssd:ParameterValues>" + parameters({"u0": (5.0, "cm")})
              + "</ssd:ParameterValues></ssd:ParameterBinding>")
    cm = f'<ssc:Unit xmlns:ssc="{SSC}" name="cm"><ssc:BaseUnit m="1" factor="0.01"/></ssc:Unit>'
    ssp = write(tmp_path, {"a": fmu}, component("a", inline), ssd_units=cm, files={"resources/a.ssv": ssv},
                system_bindings='<ssd:ParameterBinding source="resources/a.ssv"/>')
    assert params(read_ssp(ssp), "a") == {"m": 1.0, "k": 40.0, "v0": 2.0, "u0": 0.05}
    assert load(ssp).subsims["a"].params["m"] == 1.0


@pytest.mark.parametrize(("suppress", "expected"), [(False, 2.0), (True, 2000.0)])
def test_a_mapped_value_is_converted_to_its_target_variables_unit_before_the_transformation(
    tmp_path: Path, fmus: dict[str, Path], suppress: bool, expected: float
) -> None:
    """mass = 1000 g mapped to m (kg) with factor 2: 1000 g is 1 kg, times 2 (SSP: the linear transformation comes
    after the unit conversion); with suppressUnitConversion the value goes as it is given: 2 x 1000."""
    flag = ' suppressUnitConversion="true"' if suppress else ""
    entry = (f'<ssm:MappingEntry source="mass" target="m"{flag}><ssc:LinearTransformation factor="2"/>'
             "</ssm:MappingEntry>")
    ssm = f'<ssm:ParameterMapping xmlns:ssm="{SSM}" version="1.0">{entry}</ssm:ParameterMapping>'
    binding = (f'<ssd:ParameterBinding source="resources/a.ssv"><ssd:ParameterMapping>{ssm}</ssd:ParameterMapping>'
               "</ssd:ParameterBinding>")
    ssp = write(tmp_path, {"a": variant(fmus, tmp_path / "a.fmu")}, component("a", binding),
                files={"resources/a.ssv": parameters({"mass": (1000.0, "g")})})
    assert params(read_ssp(ssp), "a") == {"m": expected}


@pytest.mark.parametrize(
    ("defined", "row", "phrase"),
    [
        (False, (1000.0, "g"), "parameter 'm' is given in 'g' and FMU variable 'm' is in 'kg': cannot convert, "
                               "unit 'kg' has no definition"),
        (True, (1.0, "m"), "parameter 'm' is given in 'm' and FMU variable 'm' is in 'kg': cannot convert, "
                           "different dimensions ('m' is m, 'kg' is kg)"),
        (True, (1.0, "lb"), "parameter 'm' is given in 'lb' and FMU variable 'm' is in 'kg': cannot convert, "
                            "unit 'lb' has no definition"),
    ],
)
def test_a_parameter_unit_that_cannot_be_converted_is_one_line_naming_both(
    tmp_path: Path, fmus: dict[str, Path], defined: bool, row: tuple[float, str], phrase: str
) -> None:
    fmu = variant(fmus, tmp_path / "a.fmu", defined=defined)
    ssp = write(tmp_path, {"a": fmu}, component("a", '<ssd:ParameterBinding source="resources/a.ssv"/>'),
                files={"resources/a.ssv": parameters({"m": row})})
    with pytest.raises(ScenarioError) as err:
        read_ssp(ssp)
    assert f"component 'a': {phrase}" in str(err.value) and "\n" not in str(err.value)


def test_a_variable_unit_the_fmu_only_names_may_be_defined_in_the_parameter_set(
    tmp_path: Path, fmus: dict[str, Path]
) -> None:
    """The built FMU names kg without a BaseUnit: with kg defined beside g in the .ssv's Units, m = 1000 g is 1 kg
    (it was refused, 'unit kg has no definition', unless kg was defined in the SSD: an FMI probe)."""
    kg = f'<ssc:Unit xmlns:ssc="{SSC}" name="kg"><ssc:BaseUnit kg="1"/></ssc:Unit>'
    ssp = write(tmp_path, {"a": fmus["mass2"]}, component("a", '<ssd:ParameterBinding source="resources/a.ssv"/>'),
                files={"resources/a.ssv": parameters({"m": (1000.0, "g")}, units=kg)})
    assert params(read_ssp(ssp), "a") == {"m": 1.0}


def test_a_parameter_in_the_variables_unit_needs_no_definition(tmp_path: Path, fmus: dict[str, Path]) -> None:
    """The built FMU names kg without defining it: m = 2 kg is 2 kg all the same."""
    ssp = write(tmp_path, {"a": fmus["mass2"]}, component("a", '<ssd:ParameterBinding source="resources/a.ssv"/>'),
                files={"resources/a.ssv": parameters({"m": (2.0, "kg")})})
    assert params(read_ssp(ssp), "a") == {"m": 2.0}


@pytest.mark.parametrize(
    ("force", "inner", "suppress", "expected"),
    [
        ("mm", "", False, (1000.0, 0.0)),  # 1 m is 1000 mm
        ("mm", '<ssc:LinearTransformation factor="2" offset="3"/>', False, (2000.0, 3.0)),  # 2 (1000 x) + 3
        ("mm", '<ssc:LinearTransformation factor="2" offset="3"/>', True, (2.0, 3.0)),  # no conversion asked
        ("mm", "", True, (1.0, 0.0)),  # the user's word: the value as it is
        ("K", "", False, (1.0, 273.15)),  # u in degC: x + 273.15 K
    ],
)
def test_a_connection_between_units_of_one_quantity_converts(
    tmp_path: Path, fmus: dict[str, Path], force: str, inner: str, suppress: bool, expected: tuple[float, float]
) -> None:
    """SSP converts between the connectors' units before the LinearTransformation (the SSP 1.0 schema:
    'the value of source is already converted to the target unit'), unless suppressUnitConversion."""
    a = variant(fmus, tmp_path / "a.fmu", u="degC" if force == "K" else "m")
    b = variant(fmus, tmp_path / "b.fmu", force=force)
    ssp = write(tmp_path, {"a": a, "b": b}, component("a") + component("b"), connection(inner, suppress))
    coupling = read_ssp(ssp)["couplings"][0]
    assert coupling == {"from": "a.u", "to": "b.F", "transform": "linear",
                        "params": {"gains": [expected[0]], "offset": expected[1]}}
    assert load(ssp).couplings[0].params == coupling["params"]


def test_connectors_declared_in_the_ssd_are_converted_to_and_from_their_fmu_variables(
    tmp_path: Path, fmus: dict[str, Path]
) -> None:
    """a.u is in m in its FMU, its connector in mm (SSD); b.F is in mm in its FMU, its connector in m: the
    connection is mm -> m, so the value goes m -> mm -> m -> mm: 1000 in all, and a factor 2 in between."""
    a = variant(fmus, tmp_path / "a.fmu")
    b = variant(fmus, tmp_path / "b.fmu", force="mm")
    mm = f'<ssc:Unit xmlns:ssc="{SSC}" name="mm"><ssc:BaseUnit m="1" factor="0.001"/></ssc:Unit>' \
         f'<ssc:Unit xmlns:ssc="{SSC}" name="m"><ssc:BaseUnit m="1"/></ssc:Unit>'
    comps = (component("a", connectors='<ssd:Connector name="u" kind="output"><ssc:Real unit="mm"/></ssd:Connector>')
             + component("b", connectors='<ssd:Connector name="F" kind="input"><ssc:Real unit="m"/></ssd:Connector>'))
    ssp = write(tmp_path, {"a": a, "b": b}, comps, connection('<ssc:LinearTransformation factor="2"/>'), mm)
    assert read_ssp(ssp)["couplings"][0]["params"] == {"gains": [2000.0], "offset": 0.0}


def test_a_connection_within_one_unit_stays_an_identity_coupling(tmp_path: Path, fmus: dict[str, Path]) -> None:
    a, b = variant(fmus, tmp_path / "a.fmu", u="mm"), variant(fmus, tmp_path / "b.fmu", force="mm")
    ssp = write(tmp_path, {"a": a, "b": b}, component("a") + component("b"), connection())
    assert read_ssp(ssp)["couplings"] == [{"from": "a.u", "to": "b.F"}]


@pytest.mark.parametrize(
    ("defined", "inner", "phrase"),
    [
        (True, "", "connection a.u -> b.F: the output is in 'm' and the input in 'N': cannot convert, different "
                   "dimensions ('m' is m, 'N' is kg.m.s-2); connect ports of one quantity, or give the connection a "
                   "LinearTransformation that maps one to the other"),
        (False, "", "connection a.u -> b.F: the output is in 'm' and the input in 'N': cannot convert, unit 'm' has "
                    "no definition"),
        (True, '<ssc:LinearTransformation factor="4"/>', None),  # a spring: the transformation maps m to N
        (False, '<ssc:LinearTransformation factor="4"/>', None),
    ],
)
def test_a_connection_between_quantities_is_refused_without_a_transformation(
    tmp_path: Path, fmus: dict[str, Path], defined: bool, inner: str, phrase: str | None
) -> None:
    a = variant(fmus, tmp_path / "a.fmu", defined=defined)
    b = variant(fmus, tmp_path / "b.fmu", defined=defined)
    ssp = write(tmp_path, {"a": a, "b": b}, component("a") + component("b"), connection(inner))
    if phrase is None:
        assert read_ssp(ssp)["couplings"][0]["params"] == {"gains": [4.0], "offset": 0.0}
        return
    with pytest.raises(ScenarioError) as err:
        read_ssp(ssp)
    assert phrase in str(err.value) and "\n" not in str(err.value)


def test_a_connector_declared_in_another_quantity_than_its_fmu_variable_is_refused(
    tmp_path: Path, fmus: dict[str, Path]
) -> None:
    a, b = variant(fmus, tmp_path / "a.fmu"), variant(fmus, tmp_path / "b.fmu")
    comps = component("a", connectors='<ssd:Connector name="u" kind="output"><ssc:Real unit="N"/></ssd:Connector>')
    ssp = write(tmp_path, {"a": a, "b": b}, comps + component("b"), connection())
    with pytest.raises(ScenarioError) as err:
        read_ssp(ssp)
    assert str(err.value) == (f"{ssp}: connection a.u -> b.F: connector a.u: the connector is declared in 'N' and "
                              "its FMU variable is in 'm': cannot convert, different dimensions ('m' is m, 'N' is "
                              "kg.m.s-2)")
