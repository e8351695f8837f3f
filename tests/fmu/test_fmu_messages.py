"""What an FMU says and what it cannot take: its warnings reach the user, values it would wrap are refused, the
variables cosim does not use are named, and a problem of the FMU is not called a bad parameter."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cosim.contract import CosimError, SubsimError
from cosim.coupler.couplings import Coupling, CouplingError
from cosim.coupler.relaxation import Settings
from cosim.driver import plan_for
from cosim.handles import Description
from cosim.protocol.messages import decode_reply, encode_request
from cosim.protocol.service import answer
from cosim.results import read_results
from cosim.runtime import Runtime
from subsims.fmu.fmu import LOG_SHOWN, FmiCallError, FmuError, Instance, Variable, coerce, read_fmu
from subsims.fmu.subsim import FmuSubsim

ROOT = Path(__file__).resolve().parents[2]
T = np.linspace(0.0, 0.4, 5)  # steps at 0, 0.1, 0.2, 0.3: the FMUs warn from t = 0.25 on


def _run(path: Path, name: str) -> tuple[Runtime, np.ndarray]:
    rt = Runtime(FmuSubsim, name=name)
    rt.configure({"fmu": str(path), "u0": 0.5})
    out = rt.run_interval(T, {"F": np.zeros((5, 1))})["outputs"]["u"]
    return rt, out


@pytest.mark.parametrize("version", [2, 3])
def test_an_fmu_warning_is_printed_once_with_its_subsim_time_and_category(
        fmus: dict[str, Path], version: int, capsys: pytest.CaptureFixture[str]) -> None:
    _, quiet = _run(fmus[f"mass{version}"], "left")
    assert capsys.readouterr().err == ""
    rt, warned = _run(fmus[f"mass{version}_warn"], "left")
    rt.run_interval(T, {"F": np.zeros((5, 1))})  # the same interval again (a stage): the same warning, not shown again
    err = capsys.readouterr().err
    assert err == (f"left (mass{version}_warn.fmu): FMU warning at t=0.30000000000000004 [logStatusWarning]: "
                   "spring beyond its rated stroke\n")
    np.testing.assert_array_equal(warned, quiet)  # a warning leaves the step's result standing


def test_distinct_warnings_beyond_the_limit_are_counted_and_the_count_said_at_the_end(
        fmus: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    rt, _ = _run(fmus["mass2"], "m")
    inst: Instance = rt.model._holder[0]
    for i in range(LOG_SHOWN + 5):
        inst._log2(None, b"m", 1, b"logStatusWarning", f"warning {i}".encode())
    inst._log2(None, b"m", 0, b"logAll", b"an OK message is not shown")
    err = capsys.readouterr().err.splitlines()
    assert len(err) == LOG_SHOWN and err[0].endswith(": warning 0")
    assert err[-1].endswith(f"warning {LOG_SHOWN - 1} ({LOG_SHOWN} warnings shown: any more are counted, not shown)")
    inst.free()
    assert capsys.readouterr().err == "m (mass2.fmu): 5 more FMU warning(s) not shown\n"


def test_a_failed_call_does_not_quote_a_message_logged_by_an_earlier_call(fmus: dict[str, Path]) -> None:
    rt, _ = _run(fmus["mass2_warn"], "m")
    inst: Instance = rt.model._holder[0]
    inst.do_step(0.3, 0.1)
    assert inst.last_message == "spring beyond its rated stroke"  # logged by that step

    def fails() -> None:
        raise RuntimeError("boom")

    with pytest.raises(FmiCallError) as err:
        inst.call("fmi2Something", fails)
    assert str(err.value) == "fmi2Something: boom"


@pytest.mark.parametrize(
    ("fmi_type", "value", "phrase"),
    [
        ("Float32", 1e39, "x is Float32: 1e+39 is beyond its largest finite value, 3.40282e+38"),
        ("Int32", 2**31, "x is Int32: 2147483648 is outside its range [-2147483648, 2147483647]"),
        ("Int32", -2**31 - 1, "x is Int32: -2147483649 is outside its range"),
        ("UInt8", -1, "x is UInt8: -1 is outside its range [0, 255]"),
        ("UInt8", 256, "x is UInt8: 256 is outside its range [0, 255]"),
        ("Int64", 2**63, "x is Int64: 9223372036854775808 is outside its range"),
        ("Integer", 2**31, "x is Integer: 2147483648 is outside its range [-2147483648, 2147483647]"),
    ],
)
def test_a_value_the_fmu_type_would_wrap_or_overflow_is_refused(fmi_type: str, value: object, phrase: str) -> None:
    var = Variable("x", 1, fmi_type, "parameter", "fixed", "exact", "0", "", "")
    with pytest.raises(FmuError) as err:
        coerce(var, value, 2 if fmi_type == "Integer" else 3)
    assert str(err.value) == phrase or str(err.value).startswith(phrase)


@pytest.mark.parametrize(("fmi_type", "value"), [("Float32", 3.4e38), ("Int32", 2**31 - 1), ("Int32", -2**31),
                                                 ("UInt8", 255), ("UInt64", 2**64 - 1), ("Int64", -2**63)])
def test_values_at_the_ends_of_a_type_range_pass(fmi_type: str, value: object) -> None:
    var = Variable("x", 1, fmi_type, "parameter", "fixed", "exact", "0", "", "")
    assert coerce(var, value, 3) == value


def test_out_of_range_values_are_refused_at_configure_naming_the_variable(fmus: dict[str, Path]) -> None:
    for params, phrase in [({"mode": 2**31}, "mode is Int32: 2147483648 is outside its range"),
                           ({"level": 300}, "level is UInt8: 300 is outside its range [0, 255]"),
                           ({"gain32": 1e40}, "gain32 is Float32: 1e+40 is beyond its largest finite value")]:
        rt = Runtime(FmuSubsim)
        with pytest.raises(CosimError) as err:
            rt.configure({"fmu": str(fmus["mass3_extras"]), **params})
        assert err.value.code == "bad_value" and phrase in err.value.message, err.value.message
        assert rt.state is None


@pytest.mark.parametrize("version", [2, 3])
def test_a_value_outside_the_declared_min_and_max_is_refused(fmus: dict[str, Path], tmp_path: Path,
                                                             version: int) -> None:
    """The Reference FMUs' BouncingBall ran with e = 1.5 though it declares max 1 (an FMI probe): FMI calls a value
    outside min and max an error the FMU may not check. Refused naming the variable and its range."""
    import zipfile

    with zipfile.ZipFile(fmus[f"mass{version}"]) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    xml = members["modelDescription.xml"].decode()
    at = xml.index('<ScalarVariable name="m"' if version == 2 else '<Float64 name="m"')
    end = xml.index("/>", xml.index("<Real ", at) if version == 2 else at)
    members["modelDescription.xml"] = (xml[:end] + ' min="0.5" max="10"' + xml[end:]).encode()
    bounded = tmp_path / "bounded.fmu"
    with zipfile.ZipFile(bounded, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    for m in (0.1, 12.0):
        with pytest.raises(CosimError) as err:
            Runtime(FmuSubsim).configure({"fmu": str(bounded), "m": m})
        assert err.value.code == "bad_value" and err.value.message.endswith(
            f"m: {m!r} is outside its declared range [0.5, 10] (min and max in the FMU's model description)"), \
            err.value.message
    for m in (0.5, 10, 2.0):  # (the ends are in the range)
        Runtime(FmuSubsim).configure({"fmu": str(bounded), "m": m})


def test_an_enumeration_is_given_by_an_item_name_or_its_number(fmus: dict[str, Path], tmp_path: Path) -> None:
    """An Enumeration given by its item's name ("Option2", as a user and an SSP's .ssv give it) was refused: an
    integer was required (an FMI probe). The name is taken as its item's value; another name is refused listing the
    items."""
    import zipfile

    from subsims.fmu.fmu import FmuError, coerce

    with zipfile.ZipFile(fmus["mass2"]) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    xml = members["modelDescription.xml"].decode()
    speeds = ('<TypeDefinitions><SimpleType name="Speed"><Enumeration><Item name="Slow" value="1"/>'
              '<Item name="Fast" value="2"/></Enumeration></SimpleType></TypeDefinitions>')
    xml = xml.replace("</UnitDefinitions>", "</UnitDefinitions>" + speeds)
    xml = xml.replace("</ModelVariables>", '<ScalarVariable name="speed" valueReference="20" causality="parameter" '
                      'variability="fixed" initial="exact"><Enumeration declaredType="Speed" start="1"/>'
                      "</ScalarVariable></ModelVariables>")
    members["modelDescription.xml"] = xml.encode()
    variant = tmp_path / "speeds.fmu"
    with zipfile.ZipFile(variant, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    speed = read_fmu(variant).settable["speed"]
    assert speed.items == (("Slow", 1), ("Fast", 2))
    assert coerce(speed, "Fast", 2) == 2 and coerce(speed, 1, 2) == 1
    with pytest.raises(FmuError) as err:
        coerce(speed, "Medium", 2)
    assert str(err.value) == "speed is an Enumeration: 'Medium' is none of its items, Slow (1), Fast (2)"


def test_variables_cosim_does_not_use_are_listed_and_named_when_given(fmus: dict[str, Path]) -> None:
    info = read_fmu(fmus["mass3_extras"])
    assert info.summary()["not_used"] == {
        "gains": "an array (Float64 with dimensions): arrays are not supported",
        "bias": "an array (Float64 with dimensions): arrays are not supported",
        "count": "an Int32 output: only real outputs are ports",
        # (a structural parameter was in neither list, and given it was 'unknown FMU variable': an FMI probe)
        "rows": "a structural parameter (UInt64): structural parameters are not supported",
    }
    assert [v.name for v in info.inputs] == ["F"] and [v.name for v in info.outputs] == ["u", "v"]
    with pytest.raises(CosimError) as err:
        Runtime(FmuSubsim).configure({"fmu": str(fmus["mass3_extras"]), "gains": [2.0, 0.0]})
    assert err.value.message == ("configure: bad parameter: gains in mass3_extras.fmu is an array (Float64 with "
                                 "dimensions): arrays are not supported")
    with pytest.raises(CosimError) as err:
        Runtime(FmuSubsim).configure({"fmu": str(fmus["mass3_extras"]), "rows": 3})
    assert "rows in mass3_extras.fmu is a structural parameter (UInt64)" in err.value.message, err.value.message


def test_a_coupling_naming_a_variable_that_is_no_port_says_why(fmus: dict[str, Path]) -> None:
    """An Int32 output or input of an FMU is no port: a coupling naming one was refused as "has no output 'count'"
    (the user sees the variable in the FMU; an FMI probe). The reason travels in describe's not_ports, over the wire
    too."""
    prototype = Runtime(FmuSubsim(fmus["mass3_extras"]), name="box")  # before configure too (a review)
    assert prototype.describe()["not_ports"]["count"] == "an Int32 output: only real outputs are ports"
    rt = Runtime(FmuSubsim, name="box")
    rt.configure({"fmu": str(fmus["mass3_extras"])})
    described = decode_reply("describe", answer(rt, encode_request("describe")))
    box = Description.from_result(described)
    assert box.not_ports["count"] == "an Int32 output: only real outputs are ports"
    assert box.not_ports["gear"].startswith("an Int32 input: only real inputs are ports; give it a value among")
    assert "u" not in box.not_ports and "F" not in box.not_ports
    other = Description.from_result({**described, "name": "other", "not_ports": {}})
    settings = Settings(method="distributed")
    with pytest.raises(CouplingError) as err:
        plan_for({"box": box, "other": other}, [Coupling.make("other.F", "box.count")], settings)
    assert str(err.value) == ("coupling box.count -> other.F: 'box' has no output 'count' (outputs: u, v) "
                              "(box.count is an Int32 output: only real outputs are ports)")
    with pytest.raises(CouplingError) as err:
        plan_for({"box": box, "other": other}, [Coupling.make("box.gear", "other.u")], settings)
    assert "(box.gear is an Int32 input: only real inputs are ports; give it a value among the subsim's params" \
        in str(err.value), str(err.value)
    with pytest.raises(CouplingError) as err:  # a name that is nothing: as before
        plan_for({"box": box, "other": other}, [Coupling.make("other.F", "box.nothing")], settings)
    assert str(err.value) == "coupling box.nothing -> other.F: 'box' has no output 'nothing' (outputs: u, v)"


def test_an_fmu_that_cannot_change_its_communication_step_is_not_stepped_another(fmus: dict[str, Path],
                                                                                   tmp_path: Path) -> None:
    """canHandleVariableCommunicationStepSize="false" and interval = "auto" (or a halving): it was stepped at
    every length anyway (an FMI probe's open item; an FMU with a fixed-step solver fails, or ignores the step)."""
    import zipfile

    fixed = tmp_path / "mass2_fixed.fmu"
    with zipfile.ZipFile(fmus["mass2"]) as src, zipfile.ZipFile(fixed, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'canHandleVariableCommunicationStepSize="true"',
                                    b'canHandleVariableCommunicationStepSize="false"')
            dst.writestr(item, data)
    assert read_fmu(fixed).fixed_step
    rt = Runtime(FmuSubsim(fixed), name="fixed")  # a prototype, copied at configure (as python -m subsims.fmu serves)
    assert rt.describe()["inputs"].keys() == {"F"}
    rt.configure({"fmu": str(fixed), "u0": 0.5})
    rt.run_interval(T, {"F": np.zeros((5, 1))})
    rt.run_interval(T + 0.4, {"F": np.zeros((5, 1))}, commit=True)  # the same step: runs
    with pytest.raises(CosimError) as err:
        rt.run_interval(np.linspace(0.8, 1.0, 5), {"F": np.zeros((5, 1))}, commit=True)
    assert err.value.code == "model_error"
    assert err.value.message == ("at t in [0.8, 1.0]: mass2_fixed.fmu cannot change its communication step "
                                 "(canHandleVariableCommunicationStepSize is false): it stepped 0.1 s, this interval "
                                 "asks 0.05 s; give it a fixed [coupling] interval (not \"auto\") and max_halvings = 0")
    assert rt.time == 0.4  # nothing of the refused interval committed (its commit rode on it)


def test_an_alias_and_its_variable_given_together_are_refused(fmus: dict[str, Path]) -> None:
    rt = Runtime(FmuSubsim)
    rt.configure({"fmu": str(fmus["mass2_alias"]), "x0": 0.25})  # the alias alone sets u0
    assert rt.run_interval(T[:2], {"F": np.zeros((2, 1))})["outputs"]["u"][0, 0] == 0.25
    with pytest.raises(CosimError) as err:
        rt.configure({"fmu": str(fmus["mass2_alias"]), "u0": 0.5, "x0": 0.25})
    assert "'u0' and 'x0' in mass2_alias.fmu are one variable (aliases): give one" in err.value.message


def test_a_binary_not_named_after_the_model_identifier_is_named(fmus: dict[str, Path]) -> None:
    with pytest.raises(FmuError) as err:
        read_fmu(fmus["misnamed_binary"])
    assert "binaries/linux64/mass.so missing; binaries/linux64/ holds Mass_Model.so: the file must be named after " \
           "the modelIdentifier" in str(err.value)


def test_an_fmu_that_cannot_save_its_state_is_not_called_a_bad_parameter(fmus: dict[str, Path]) -> None:
    with pytest.raises(CosimError) as err:
        Runtime(FmuSubsim).configure({"fmu": str(fmus["mass2_nostate"])})
    assert err.value.code == "model_error" and "bad parameter" not in err.value.message
    with pytest.raises(CosimError) as err:  # its binary cannot load: the FMU's fault too
        Runtime(FmuSubsim).configure({"fmu": str(fmus["bad_binary"])})
    assert err.value.code == "model_error" and err.value.message.startswith("configure: ") \
        and "cannot load the binary" in err.value.message


@pytest.mark.parametrize("version", [2, 3])
def test_a_step_the_fmu_discards_asks_for_a_shorter_interval_and_changes_nothing(fmus: dict[str, Path],
                                                                                 version: int) -> None:
    """fmi2Discard (FMI 3: Discard) was a model error that ended the run; FMI's meaning is 'try a shorter step'."""
    rt = Runtime(FmuSubsim)
    rt.configure({"fmu": str(fmus[f"mass{version}_discard"]), "u0": 0.5})
    committed = rt.state.copy()
    with pytest.raises(CosimError) as err:
        rt.run_interval(T, {"F": np.zeros((5, 1))})  # steps of 0.1 s
    assert err.value.code == "too_long" and "(discard)" in err.value.message
    assert "step too long for the spring" in err.value.message
    assert np.array_equal(rt.state, committed)
    out = rt.run_interval(np.linspace(0.0, 0.04, 5), {"F": np.zeros((5, 1))})  # steps of 0.01 s: taken
    assert out["outputs"]["u"][0, 0] == 0.5


def _mixed(tmp_path: Path, fmu: Path, interval: str) -> Path:
    text = (ROOT / "scenarios" / "fmu" / "oscillator_mixed.toml").read_text()
    text = text.replace('fmu = "mass3.fmu"', f'fmu = "{fmu}"').replace('interface = "me", ', "")
    text = text.replace("interval = 0.01", f"interval = {interval}")
    scenario = tmp_path / "mixed.toml"
    scenario.write_text(text)
    return scenario


def test_with_automatic_intervals_a_discarded_step_is_taken_again_shorter(fmus: dict[str, Path],
                                                                          tmp_path: Path) -> None:
    from cosim.runner import run_scenario
    from cosim.scenario import load

    fixed = _mixed(tmp_path, fmus["mass2_discard"], "0.1")  # 0.025 s between samples: every step discarded
    with pytest.raises(SubsimError) as err:
        run_scenario(load(fixed), stop=0.3, output=tmp_path / "f.csv", inprocess=True, progress=False,
                     log=lambda m: None)
    assert err.value.code == "too_long"
    assert "a shorter [coupling] interval is the cure" in "".join(getattr(err.value, "__notes__", []))
    auto = _mixed(tmp_path, fmus["mass2_discard"], '"auto"\ninterval_initial = 0.1')
    report = run_scenario(load(auto), stop=0.3, output=tmp_path / "a.csv", inprocess=True, progress=False,
                          log=lambda m: None)
    assert report.summary.t_end == 0.3 and report.summary.unconverged >= 1  # the discarded tries, retried shorter
    cols, diag = read_results(tmp_path / "a.csv.diag.csv")
    assert (diag[:, cols.index("length_s")] / 4 <= 0.02 + 1e-15).all()  # every step taken is one it accepts
