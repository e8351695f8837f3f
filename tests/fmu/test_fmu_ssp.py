"""SSP import (``cosim run system.ssp``) and the ``fmu = "path.fmu"`` scenario shorthand."""

from __future__ import annotations

import os
import shutil
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cosim.cli import main as cosim_main
from cosim.results import read_results
from cosim.runner import run_scenario
from cosim.scenario import ScenarioError, load
from subsims.fmu.ssp import read_ssp

pytestmark = [pytest.mark.slow]  # the inner loop: pytest -m "not slow"

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios" / "fmu"
K12 = 16 * np.pi**2
K = 20 * np.pi**2
SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
SSM = "http://ssp-standard.org/SSP1/SystemStructureParameterMapping"


def parameter_set(values: dict[str, float]) -> str:
    rows = "".join(f'<ssv:Parameter name="{n}"><ssv:Real value="{v!r}"/></ssv:Parameter>' for n, v in values.items())
    return f'<ssv:ParameterSet xmlns:ssv="{SSV}" version="1.0" name="p"><ssv:Parameters>{rows}</ssv:Parameters>' \
           "</ssv:ParameterSet>"


def ssd(components: str, connections: str, experiment: str = '<ssd:DefaultExperiment startTime="0" stopTime="0.5"/>',
        system_bindings: str = "") -> str:
    """``system_bindings``: ParameterBinding elements of the system itself."""
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<ssd:SystemStructureDescription xmlns:ssd="{SSD}" '
            f'xmlns:ssc="{SSC}" xmlns:ssv="{SSV}" version="1.0" name="oscillator-ssp"><ssd:System name="top">'
            f"<ssd:ParameterBindings>{system_bindings}</ssd:ParameterBindings>"
            f"<ssd:Elements>{components}</ssd:Elements><ssd:Connections>{connections}</ssd:Connections>"
            f"</ssd:System>{experiment}</ssd:SystemStructureDescription>")


def component(name: str, bindings: str, source: str = "resources/mass.fmu",
              kind: str = "application/x-fmu-sharedlibrary") -> str:
    return (f'<ssd:Component name="{name}" type="{kind}" source="{source}"><ssd:Connectors>'
            '<ssd:Connector name="F" kind="input"><ssc:Real/></ssd:Connector>'
            '<ssd:Connector name="u" kind="output"><ssc:Real/></ssd:Connector>'
            f"</ssd:Connectors><ssd:ParameterBindings>{bindings}</ssd:ParameterBindings></ssd:Component>")


def connection(start: str, end: str, factor: float | None = K12, layout: bool = False) -> str:
    """``layout``: with the drawing an SSP editor adds (a ConnectionGeometry and Annotations), which couple nothing."""
    (se, sc), (ee, ec) = start.split("."), end.split(".")
    inner = "" if factor is None else f'<ssc:LinearTransformation factor="{factor!r}" offset="0"/>'
    if layout:
        inner += ('<ssd:ConnectionGeometry pointsX="10 20" pointsY="5 5"/>'
                  '<ssc:Annotations><ssc:Annotation type="com.example.editor"/></ssc:Annotations>')
    return (f'<ssd:Connection startElement="{se}" startConnector="{sc}" endElement="{ee}" endConnector="{ec}">'
            f"{inner}</ssd:Connection>")


def mapping(entries: str, inline: bool = True) -> str:
    """A ParameterMapping of ``entries`` (MappingEntry elements): inline, or the ``.ssm`` file's text."""
    ssm = f'<ssm:ParameterMapping xmlns:ssm="{SSM}" version="1.0">{entries}</ssm:ParameterMapping>'
    return f"<ssd:ParameterMapping>{ssm}</ssd:ParameterMapping>" if inline else ssm


def oscillator_ssd() -> str:
    """mass1: an inline parameter set whose mass (in grams) a ParameterMapping turns into the FMU's m (in kg);
    mass2: a file of bare names, bound on the system with the prefix 'mass2.' (SSP puts it before each name)."""
    scale = ('<ssm:MappingEntry source="mass_g" target="m"><ssc:LinearTransformation factor="0.001"/>'
             "</ssm:MappingEntry>")
    inline = (f"<ssd:ParameterBinding><ssd:ParameterValues>{parameter_set({'mass_g': 1000.0, 'k': K, 'u0': 1.0})}"
              f"</ssd:ParameterValues>{mapping(scale)}</ssd:ParameterBinding>")
    on_system = '<ssd:ParameterBinding source="resources/mass2.ssv" prefix="mass2."/>'
    return ssd(component("mass1", inline) + component("mass2", ""),
               connection("mass2.u", "mass1.F", layout=True) + connection("mass1.u", "mass2.F"),
               system_bindings=on_system)


def write_ssp(path: Path, ssd_text: str | None, fmu: Path | None, extra: dict[str, str] | None = None) -> Path:
    with zipfile.ZipFile(path, "w") as zf:
        if ssd_text is not None:
            zf.writestr("SystemStructure.ssd", ssd_text)
        if fmu is not None:
            zf.write(fmu, "resources/mass.fmu")
        for name, text in (extra or {}).items():
            zf.writestr(name, text)
    return path


COMPANION = """\
[coupling]
method = "centralized"
interval = 0.02
samples = 21
first_guess = "extrapolate"
interp = "linear"
tol = 1e-12
res = 1e-13
max_stages = 60
"""


def test_cosim_run_ssp_gives_the_same_run_as_the_toml_scenario(
    tmp_path: Path, fmus: dict[str, Path], capsys: pytest.CaptureFixture
) -> None:
    """The SSP (an inline parameter set with a mapping, an .ssv bound on the system with a prefix, linear
    transformations, DefaultExperiment) plus a companion TOML with the coupling settings is the scenario
    scenarios/fmu/oscillator_fmu.toml with method centralized: the run over Zenoh must be bit for bit the same."""
    ssv = parameter_set({"m": 1.0, "k": K})
    ssp = write_ssp(tmp_path / "system.ssp", oscillator_ssd(), fmus["mass2"], {"resources/mass2.ssv": ssv})
    (tmp_path / "system.toml").write_text(COMPANION)

    raw = read_ssp(ssp)
    assert raw["stop"] == 0.5 and raw["coupling"]["method"] == "centralized"
    assert {n: {k: v for k, v in s["params"].items() if k != "fmu"} for n, s in raw["subsims"].items()} == {
        "mass1": {"m": 1.0, "k": K, "u0": 1.0}, "mass2": {"m": 1.0, "k": K}}
    assert raw["couplings"][0] == {"to": "mass1.F", "from": "mass2.u", "transform": "linear",
                                   "params": {"gains": [K12], "offset": 0.0}}

    out = tmp_path / "ssp.csv"
    code = cosim_main(["run", str(ssp), "--output", str(out), "--quiet"])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert printed.out.startswith("oscillator-ssp (centralized): 25 intervals to t = 0.5")

    shutil.copy(fmus["mass2"], tmp_path / "mass2.fmu")
    shutil.copy(SCENARIOS / "oscillator_fmu.toml", tmp_path / "scenario.toml")
    ref = tmp_path / "toml.csv"
    run_scenario(load(tmp_path / "scenario.toml"), method="centralized", stop=0.5, output=ref, inprocess=True,
                 progress=False)
    cols, data = read_results(out)
    cols_ref, data_ref = read_results(ref)
    assert cols == cols_ref and data.shape == data_ref.shape == (501, 5)
    assert np.array_equal(data, data_ref)


@pytest.mark.parametrize(
    ("case", "phrase"),
    [
        ("no_ssd", "not an SSP file (no SystemStructure.ssd in the archive)"),
        ("not_fmu", "component 'mass1': only FMU components are supported"),
        ("missing_fmu", "component 'mass1': its FMU 'resources/other.fmu' is not in the archive"),
        ("system_connector", "connection top.u -> mass1.F: system-level connectors are not supported"),
        ("signal_dictionary", "system 'top': signal dictionaries (SignalDictionaries) are not supported"),
        ("mapped_twice", "component 'mass1': parameter mapping (inline) maps 'mass' twice"),
        ("enumeration_mapping", "component 'mass1': parameter mapping 'resources/m.ssm', entry 'mass': "
                                "EnumerationMappingTransformation is not supported"),
        ("no_map_entry", "component 'mass1': parameter 'n' mapped to 'n': its IntegerMappingTransformation has no "
                         "MapEntry for the value 3 (sources: [1, 2])"),
        ("missing_ssm", "component 'mass1': parameter mapping 'resources/none.ssm' is not in the archive"),
        ("in_the_fmu", "component 'mass1': a parameter file inside the component's FMU (sourceBase='component', "
                       "'resources/m.ssv') is not supported; put it in the SSP archive"),
        ("no_component", "system 'top': parameter 'mass' names no component's variable (a system's parameters are "
                         "named <component>.<variable>; components: ['mass1'])"),
        ("bad_implementation", "component 'mass1': implementation 'Both' is not one of ['CoSimulation', "
                               "'ModelExchange', 'any']"),
        ("no_stop", "no stop time: give DefaultExperiment stopTime in the SSD or stop = ... in system.toml"),
        ("bad_companion", "system.toml: [subsims.mass9] is not a component of system.ssp"),
        ("no_interval", "no coupling interval: give [coupling] interval = ... (and samples) in system.toml beside it"),
        ("missing_ssv", "parameter file 'resources/nope.ssv' is not in the archive"),
    ],
)
def test_a_bad_ssp_is_one_clear_line(
    tmp_path: Path, fmus: dict[str, Path], capsys: pytest.CaptureFixture, case: str, phrase: str
) -> None:
    plain = component("mass1", "")
    from_file = '<ssd:ParameterBinding source="resources/m.ssv">{}</ssd:ParameterBinding>'
    twice = mapping('<ssm:MappingEntry source="mass" target="m"/><ssm:MappingEntry source="mass" target="k"/>')
    integers = ('<ssv:Parameter name="n"><ssv:Integer value="3"/></ssv:Parameter>')
    integer_set = parameter_set({}).replace("<ssv:Parameters>", f"<ssv:Parameters>{integers}")
    integer_map = mapping('<ssm:MappingEntry source="n" target="n"><ssc:IntegerMappingTransformation>'
                          '<ssc:MapEntry source="1" target="10"/><ssc:MapEntry source="2" target="20"/>'
                          "</ssc:IntegerMappingTransformation></ssm:MappingEntry>")
    dictionary = ('<ssd:SignalDictionaries><ssd:SignalDictionary name="sigs"><ssd:DictionaryEntry name="s1">'
                  "<ssc:Real/></ssd:DictionaryEntry></ssd:SignalDictionary></ssd:SignalDictionaries>")
    text = {
        "no_ssd": None,
        "not_fmu": ssd(component("mass1", "", kind="application/x-ssp-package", source="resources/x.ssp"), ""),
        "missing_fmu": ssd(component("mass1", "", source="resources/other.fmu"), ""),
        "system_connector": ssd(plain, '<ssd:Connection startConnector="u" endElement="mass1" endConnector="F"/>'),
        "no_stop": ssd(plain, "", experiment=""),
        "bad_companion": ssd(plain, ""),
        "no_interval": ssd(plain, ""),
        "missing_ssv": ssd(component("mass1", '<ssd:ParameterBinding source="resources/nope.ssv"/>'), ""),
        "signal_dictionary": ssd(plain, "").replace("</ssd:Connections>", "</ssd:Connections>" + dictionary),
        "mapped_twice": ssd(component("mass1", from_file.format(twice)), ""),
        "enumeration_mapping": ssd(component("mass1", from_file.format(
            '<ssd:ParameterMapping source="resources/m.ssm"/>')), ""),
        "no_map_entry": ssd(component("mass1", "<ssd:ParameterBinding><ssd:ParameterValues>"
                                               f"{integer_set}</ssd:ParameterValues>{integer_map}"
                                               "</ssd:ParameterBinding>"), ""),
        "missing_ssm": ssd(component("mass1", from_file.format('<ssd:ParameterMapping source="resources/none.ssm"/>')),
                           ""),
        "in_the_fmu": ssd(component("mass1", '<ssd:ParameterBinding source="resources/m.ssv" sourceBase="component"/>'),
                          ""),
        "no_component": ssd(plain, "", system_bindings=from_file.format("")),
        "bad_implementation": ssd(component("mass1", "").replace("<ssd:Component ",
                                                                 '<ssd:Component implementation="Both" '), ""),
    }[case]
    enumerations = ('<ssm:MappingEntry source="mass" target="m"><ssc:EnumerationMappingTransformation>'
                    '<ssc:MapEntry source="a" target="b"/></ssc:EnumerationMappingTransformation></ssm:MappingEntry>')
    files = {"resources/m.ssv": parameter_set({"mass": 2.0}),
             "resources/m.ssm": mapping(enumerations, inline=False).replace("<ssm:ParameterMapping ",
                                                                           f'<ssm:ParameterMapping xmlns:ssc="{SSC}" ')}
    ssp = write_ssp(tmp_path / "system.ssp", text, fmus["mass2"], files)
    if case == "bad_companion":
        (tmp_path / "system.toml").write_text("[subsims.mass9.params]\nm = 2.0\n")
    with pytest.raises(ScenarioError) as err:
        load(ssp)
    assert phrase in str(err.value) and "\n" not in str(err.value)
    assert cosim_main(["run", str(ssp), "--quiet"]) == 2
    assert capsys.readouterr().err == f"cosim: {err.value}\n"


def raw_params(raw: dict, name: str) -> dict:
    return {k: v for k, v in raw["subsims"][name]["params"].items() if k != "fmu"}


def test_the_systems_bindings_win_over_the_components_and_a_prefix_goes_before_each_name(
    tmp_path: Path, fmus: dict[str, Path]
) -> None:
    """SSP: a binding on the system names <component>.<variable>; its values win over a component's own bindings;
    among one element's bindings the later wins; a binding's prefix is put before every name of its set (a set of
    bare names bound on the system with prefix 'mass2.' sets mass2's variables). System bindings were ignored
    without a word, and the prefix was taken off names instead of put before them."""
    own = f"<ssd:ParameterBinding><ssd:ParameterValues>{parameter_set({'m': 2.0, 'k': 3.0})}</ssd:ParameterValues>" \
          "</ssd:ParameterBinding>"
    on_system = ('<ssd:ParameterBinding source="resources/all.ssv"/>'
                 '<ssd:ParameterBinding source="resources/bare.ssv" prefix="mass2."/>'
                 '<ssd:ParameterBinding source="resources/later.ssv"/>')
    files = {"resources/all.ssv": parameter_set({"mass1.m": 5.0, "mass2.m": 6.0, "mass2.k": 7.0}),
             "resources/bare.ssv": parameter_set({"m": 8.0, "u0": 0.5}),
             "resources/later.ssv": parameter_set({"mass2.u0": 0.25})}
    text = ssd(component("mass1", own) + component("mass2", own), "", system_bindings=on_system)
    (tmp_path / "system.toml").write_text(COMPANION)
    raw = read_ssp(write_ssp(tmp_path / "system.ssp", text, fmus["mass2"], files))
    assert raw_params(raw, "mass1") == {"m": 5.0, "k": 3.0}
    assert raw_params(raw, "mass2") == {"m": 8.0, "k": 7.0, "u0": 0.25}


@pytest.mark.parametrize("inline", [True, False])
def test_a_parameter_mapping_renames_and_transforms_values(tmp_path: Path, fmus: dict[str, Path],
                                                           inline: bool) -> None:
    """MappingEntry source -> target, with a LinearTransformation (factor x value + offset) or a table of
    booleans or integers; a name no entry lists keeps its name and value; inline or from an .ssm file."""
    entries = ('<ssm:MappingEntry source="stiffness" target="k"><ssc:LinearTransformation factor="2" offset="1"/>'
               '</ssm:MappingEntry><ssm:MappingEntry source="mass" target="m"/>'
               '<ssm:MappingEntry source="on" target="flag"><ssc:BooleanMappingTransformation>'
               '<ssc:MapEntry source="true" target="false"/><ssc:MapEntry source="false" target="true"/>'
               "</ssc:BooleanMappingTransformation></ssm:MappingEntry>"
               '<ssm:MappingEntry source="gear" target="n"><ssc:IntegerMappingTransformation>'
               '<ssc:MapEntry source="1" target="10"/><ssc:MapEntry source="2" target="20"/>'
               "</ssc:IntegerMappingTransformation></ssm:MappingEntry>"
               '<ssm:MappingEntry source="teeth" target="z"><ssc:LinearTransformation factor="2"/></ssm:MappingEntry>')
    rows = ('<ssv:Parameter name="on"><ssv:Boolean value="true"/></ssv:Parameter>'
            '<ssv:Parameter name="gear"><ssv:Integer value="2"/></ssv:Parameter>'
            '<ssv:Parameter name="teeth"><ssv:Integer value="3"/></ssv:Parameter>'
            '<ssv:Parameter name="rtol"><ssv:Real value="0.001"/></ssv:Parameter>'
            '<ssv:Parameter name="mode"><ssv:Enumeration value="Fast"/></ssv:Parameter>')
    values = parameter_set({"stiffness": 20.0, "mass": 1.5, "u0": 0.1}).replace("</ssv:Parameters>",
                                                                                f"{rows}</ssv:Parameters>")
    ssm = mapping(entries, inline=False).replace("<ssm:ParameterMapping ", f'<ssm:ParameterMapping xmlns:ssc="{SSC}" ')
    how = mapping(entries) if inline else '<ssd:ParameterMapping source="resources/p.ssm"/>'
    binding = f'<ssd:ParameterBinding source="resources/p.ssv">{how}</ssd:ParameterBinding>'
    ssp = write_ssp(tmp_path / "system.ssp", ssd(component("mass1", binding), ""), fmus["mass2"],
                    {"resources/p.ssv": values, "resources/p.ssm": ssm})
    (tmp_path / "system.toml").write_text(COMPANION)
    # (an Integer through a linear map stays an integer; a variable named as a subsim setting, rtol, goes in the
    # values table, not over the solver's rtol: a review)
    params = raw_params(read_ssp(ssp), "mass1")
    assert params == {"k": 41.0, "m": 1.5, "u0": 0.1, "flag": False, "n": 20, "z": 6, "values": {"rtol": 0.001},
                      "mode": "Fast"}  # (an Enumeration by its item's name: the FMU subsim takes it so)
    assert type(params["z"]) is int


def test_fmu_shorthand_resolves_against_the_scenario_and_refuses_model_too(tmp_path: Path,
                                                                         fmus: dict[str, Path]) -> None:
    (tmp_path / "sub").mkdir()
    path = tmp_path / "sub" / "s.toml"
    path.write_text('start = 2.0\nstop = 3.0\n[coupling]\ninterval = 0.5\n[subsims.a]\nfmu = "../m.fmu"\n'
                    'params = { k = 1.0 }\n')
    with pytest.raises(ScenarioError) as err:  # launched on this machine: the file must be there
        load(path)
    assert str(err.value) == f"{path}: [subsims.a.fmu] no such file: {tmp_path / 'm.fmu'}"
    (tmp_path / "m.fmu").write_bytes(b"")  # a broken FMU is its fmu = line's fault, said at load (was: params)
    with pytest.raises(ScenarioError) as err:
        load(path)
    assert str(err.value) == f"{path}: [subsims.a.fmu] {tmp_path / 'm.fmu'}: not an FMU (not a zip archive)"
    shutil.copy(fmus["mass2"], tmp_path / "m.fmu")
    spec = load(path).subsims["a"]
    assert spec.model == "subsims.fmu:FmuSubsim"
    assert spec.params == {"k": 1.0, "fmu": str(tmp_path / "m.fmu"), "start_time": 2.0}
    path.write_text('stop = 1.0\n[coupling]\ninterval = 0.5\n[subsims.a]\nfmu = "m.fmu"\n'
                    'model = "subsims.fmu:FmuSubsim"\n')
    with pytest.raises(ScenarioError, match=r"\[subsims.a\] give fmu or model, not both"):
        load(path)
    path.write_text('stop = 1.0\n[coupling]\ninterval = 0.5\n[subsims.a]\nfmu = "elsewhere.fmu"\nexternal = true\n')
    assert load(path).subsims["a"].params["fmu"] == str(tmp_path / "sub" / "elsewhere.fmu")  # its own copy there
    # what an FMI probe met: params.fmu beside fmu = ... was dropped without a word; a directory was "no such file";
    # an FMU given to cosim run was "not a text file"
    path.write_text('stop = 1.0\n[coupling]\ninterval = 0.5\n[subsims.a]\nfmu = "../m.fmu"\n'
                    'params = { fmu = "other.fmu" }\n')
    with pytest.raises(ScenarioError) as err:
        load(path)
    assert str(err.value) == (f"{path}: [subsims.a] names its FMU twice, fmu = '../m.fmu' and params.fmu = "
                              "'other.fmu': give fmu = ... only")
    (tmp_path / "d.fmu").mkdir()
    path.write_text('stop = 1.0\n[coupling]\ninterval = 0.5\n[subsims.a]\nfmu = "../d.fmu"\n')
    with pytest.raises(ScenarioError) as err:
        load(path)
    assert str(err.value) == f"{path}: [subsims.a.fmu] a directory, not an .fmu file: {tmp_path / 'd.fmu'}"
    (tmp_path / "m.fmu").write_bytes(b"PK\x03\x04\xff\xfe")
    with pytest.raises(ScenarioError) as err:
        load(tmp_path / "m.fmu")
    assert str(err.value) == (f"{tmp_path / 'm.fmu'}: a .fmu file, not a scenario: couple it in a scenario (TOML), in "
                              "a [subsims.<name>] table with fmu = 'm.fmu'")


@pytest.mark.parametrize("name", ["../../cosim-test-escaped", "mass.1"])
def test_a_component_name_that_is_no_subsim_name_is_refused_before_anything_is_written(
    tmp_path: Path, fmus: dict[str, Path], name: str
) -> None:
    """The component's name becomes the directory its FMU is extracted to (in the temporary directory): a
    name with '../' wrote the FMU outside it before the name was checked. A name with '.' could not be
    coupled (signal names are 'subsim.port')."""
    name = name.replace("escaped", f"escaped-{os.getpid()}")
    escaped = Path(tempfile.gettempdir()) / f"cosim-test-escaped-{os.getpid()}"
    ssp = write_ssp(tmp_path / "system.ssp", ssd(component(name, ""), ""), fmus["mass2"])
    with pytest.raises(ScenarioError) as err:
        read_ssp(ssp)
    assert f"component {name!r}: subsim name {name!r}" in str(err.value) and "\n" not in str(err.value)
    assert not escaped.exists()


@pytest.mark.parametrize(("system", "expected"), [("Plant/Controller", "Plant_Controller"), ("..", "system"),
                                                  ("", "system"), ("a\\b", "a_b")])
def test_a_system_name_that_is_a_path_still_names_a_results_file(tmp_path: Path, fmus: dict[str, Path], system: str,
                                                                 expected: str) -> None:
    """The system's name names the default results file, results/<name>-<method>.csv: a tool's "Plant/Controller"
    became a path (or, now that a scenario's name is checked, an error the SSP's user cannot edit away)."""
    text = oscillator_ssd().replace('name="oscillator-ssp"', f'name="{system}"')
    ssp = write_ssp(tmp_path / "system.ssp", text, fmus["mass2"], {"resources/mass2.ssv": parameter_set({"m": 1.0})})
    (tmp_path / "system.toml").write_text(COMPANION)
    assert read_ssp(ssp)["name"] == expected


def test_the_companions_start_reaches_every_fmu(tmp_path: Path, fmus: dict[str, Path]) -> None:
    """A companion ``start`` overrides DefaultExperiment's, for the FMUs too: each is initialized there
    (they were initialized at DefaultExperiment's start, and a strict FMU refused the first step)."""
    ssv = {"resources/mass2.ssv": parameter_set({"mass2.m": 1.0, "mass2.k": K})}
    ssp = write_ssp(tmp_path / "system.ssp", oscillator_ssd(), fmus["mass2"], ssv)
    (tmp_path / "system.toml").write_text("start = 0.25\n" + COMPANION)
    raw = read_ssp(ssp)
    assert raw["start"] == 0.25
    assert {n: s["params"]["start_time"] for n, s in raw["subsims"].items()} == {"mass1": 0.25, "mass2": 0.25}
    late = ssd(component("mass1", ""), "", '<ssd:DefaultExperiment startTime="0.5" stopTime="1"/>')
    ssp = write_ssp(tmp_path / "late.ssp", late, fmus["mass2"])
    (tmp_path / "late.toml").write_text("start = 0.0\n" + COMPANION)
    raw = read_ssp(ssp)
    assert raw["start"] == 0.0 and "start_time" not in raw["subsims"]["mass1"]["params"]


@pytest.mark.parametrize(
    ("implementation", "companion", "interface"),
    [("ModelExchange", "", "me"), ("CoSimulation", "", "cs"), ("any", "", None), (None, "", None),
     ("ModelExchange", '[subsims.mass1.params]\ninterface = "cs"\n', "cs")],
)
def test_a_components_implementation_chooses_the_fmu_interface(
    tmp_path: Path, fmus: dict[str, Path], implementation: str | None, companion: str, interface: str | None
) -> None:
    """SSP: implementation="ModelExchange"/"CoSimulation" must be used (it was ignored: the subsim took
    co-simulation); "any" or none leaves the subsim its default; the companion TOML has the last word."""
    text = ssd(component("mass1", ""), "")
    if implementation is not None:
        text = text.replace("<ssd:Component ", f'<ssd:Component implementation="{implementation}" ')
    ssp = write_ssp(tmp_path / "system.ssp", text, fmus["mass2"])
    (tmp_path / "system.toml").write_text(COMPANION + companion)
    assert read_ssp(ssp)["subsims"]["mass1"]["params"].get("interface") == interface
    assert load(ssp).subsims["mass1"].params.get("interface") == interface


def test_an_implementation_the_fmu_does_not_have_is_refused(tmp_path: Path, fmus: dict[str, Path]) -> None:
    """SSP: 'It is an error if the specified type of FMU implementation is not present in the FMU'."""
    with zipfile.ZipFile(fmus["mass2"]) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    xml = members["modelDescription.xml"].decode()
    start = xml.index("<ModelExchange ")
    members["modelDescription.xml"] = (xml[:start] + xml[xml.index("/>", start) + 2:]).encode()
    cs_only = tmp_path / "cs_only.fmu"
    with zipfile.ZipFile(cs_only, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    text = ssd(component("mass1", "").replace("<ssd:Component ", '<ssd:Component implementation="ModelExchange" '), "")
    ssp = write_ssp(tmp_path / "system.ssp", text, cs_only)
    with pytest.raises(ScenarioError) as err:
        read_ssp(ssp)
    assert str(err.value) == (f"{ssp}: component 'mass1': implementation 'ModelExchange', but its FMU "
                              "'resources/mass.fmu' offers CoSimulation")
