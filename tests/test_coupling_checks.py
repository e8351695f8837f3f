"""Checks of the couplings against the subsims' declared ports, before any run: an identity coupling joins ports of
one unit, and an input driven twice says how to add its sources."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from cosim.coupler.couplings import Coupling, CouplingError, check_couplings, check_units

UNITS_IN = {"wheel": {"omega": "deg/s", "free": "", "phi": "rad", "torque": "N*m"}}
UNITS_OUT = {"att": {"omega": "rad/s", "phi": "rad", "raw": "", "torque": "N m"}}


@pytest.mark.parametrize(("source", "target", "refused"), [
    ("att.omega", "wheel.omega", True),   # rad/s into deg/s: a factor of 57 nobody asked for
    ("att.phi", "wheel.phi", False),      # the same unit
    ("att.raw", "wheel.omega", False),    # a port without a unit says nothing to compare
    ("att.omega", "wheel.free", False),
    ("att.torque", "wheel.torque", False),  # 'N m' is 'N*m' (it was refused, with a gain to convert: newcomer probe)
])
def test_an_identity_coupling_joins_ports_of_one_unit(source: str, target: str, refused: bool) -> None:
    couplings = [Coupling.make("wheel.phi", "att.phi"), Coupling.make(target, source)]
    if not refused:
        check_units(couplings, UNITS_IN, UNITS_OUT)
        return
    with pytest.raises(CouplingError) as err:
        check_units(couplings, UNITS_IN, UNITS_OUT)
    assert err.value.index == 1
    assert str(err.value) == ("coupling att.omega -> wheel.omega: units differ, the output is in 'rad/s' and the input "
                              "takes 'deg/s': if it is one quantity in two units, convert with a transform "
                              "(transform = \"gain\", params = { k = ... }) or declare the ports in one unit; if not, "
                              "the coupling joins the wrong ports")


@pytest.mark.parametrize(("source_unit", "target_unit"), [("K", "degC"), ("\u00b0F", "K")])
def test_temperatures_in_two_scales_are_told_to_convert_with_an_offset(source_unit: str, target_unit: str) -> None:
    """K to degC was told to convert with a gain, which cannot (a legacy-code probe)."""
    with pytest.raises(CouplingError) as err:
        check_units([Coupling.make("ctl.T", "panel.T")], {"ctl": {"T": target_unit}}, {"panel": {"T": source_unit}})
    assert ("convert with a transform (transform = \"linear\", params = { gains = [1.0], offset = ... }: a scale with "
            "an offset, K = degC + 273.15)") in str(err.value), err.value
    for other in ({"ctl": {"T": "F"}}, {"panel": {"T": "C"}}), ({"ctl": {"T": "degC"}}, {"panel": {"T": "\u00b0C"}}):
        with pytest.raises(CouplingError) as err:  # coulomb and farad; one scale spelled two ways: no offset
            check_units([Coupling.make("ctl.T", "panel.T")], *other)
        assert "(transform = \"gain\", params = { k = ... })" in str(err.value)


def test_every_coupling_between_other_units_is_named_at_once() -> None:
    couplings = [Coupling.make("wheel.omega", "att.omega"), Coupling.make("wheel.phi", "att.phi"),
                 Coupling.make("wheel.free", "att.raw"), Coupling.make("wheel.phi", "att.omega")]
    with pytest.raises(CouplingError) as err:
        check_units(couplings, UNITS_IN, UNITS_OUT)
    assert err.value.index == 0 and str(err.value).endswith(
        "if not, the coupling joins the wrong ports; also [couplings[3]] coupling att.omega -> wheel.phi: units "
        "differ, the output is in 'rad/s' and the input takes 'rad'"), err.value


def test_a_transform_may_convert_units() -> None:
    check_units([Coupling.make("wheel.omega", "att.omega", "gain", {"k": 57.29577951308232})], UNITS_IN, UNITS_OUT)


def test_an_input_driven_twice_is_told_how_to_add_its_sources() -> None:
    couplings = [Coupling.make("b.u", "a.y"), Coupling.make("b.u", "c.y")]
    with pytest.raises(CouplingError) as err:
        check_couplings(couplings, {"b": {"u": 1}}, {"a": {"y": 1}, "c": {"y": 1}})
    assert str(err.value) == ("input b.u is driven twice: by a.y -> b.u and by c.y -> b.u; to add them, give one "
                              "coupling every source in its from, with transform = \"linear\" (params = { gains = "
                              "[...] }) or a function of your own")


def test_cosim_run_refuses_a_unit_mismatch_before_the_first_interval(tmp_path: Path) -> None:
    (tmp_path / "wheel.py").write_text(
        "import numpy as np\nfrom cosim import Port, Subsim\n\n\n"
        "class Wheel(Subsim):\n"
        "    inputs = {'omega': Port(1, 'deg/s')}\n"
        "    outputs = {'h': Port(1, 'N m s')}\n\n"
        "    def initial_state(self, params):\n        return np.zeros(1)\n\n"
        "    def advance(self, state, times, u):\n        return {'h': np.zeros((times.size, 1))}, state\n")
    oscillator = (Path(__file__).parents[1] / "scenarios" / "oscillator.toml").read_text()
    (tmp_path / "s.toml").write_text(oscillator + '\n[subsims.wheel]\nmodel = "wheel:Wheel"\n\n'
                                     '[[couplings]]\nto = "wheel.omega"\nfrom = "mass1.v"\n')
    done = subprocess.run([sys.executable, "-m", "cosim.cli", "run", "s.toml", "--inprocess", "--quiet"],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert "coupling mass1.v -> wheel.omega: units differ, the output is in 'm/s' and the input takes 'deg/s'" \
        in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not [p for p in (tmp_path / "results").rglob("*")]  # nothing was written


def test_a_port_on_the_wrong_side_of_a_coupling_is_said_to_be_swapped() -> None:
    """to = an output and from = an input read only "has no input 'torque' (inputs: ...)" (a five-subsim probe)."""
    inputs, outputs = {"adcs": {"q": 4}, "att": {"torque": 3}}, {"adcs": {"torque": 3}, "att": {"q": 4}}
    with pytest.raises(CouplingError) as err:
        check_couplings([Coupling.make("adcs.torque", "att.torque")], inputs, outputs)
    assert str(err.value) == ("coupling att.torque -> adcs.torque: 'adcs' has no input 'torque' (inputs: q); it is an "
                              "output there: are to and from swapped?")
    with pytest.raises(CouplingError) as err:
        check_couplings([Coupling.make("att.torque", "adcs.q")], inputs, outputs)
    assert str(err.value).endswith("'adcs' has no output 'q' (outputs: torque); it is an input there: are to and "
                                   "from swapped?")
    with pytest.raises(CouplingError) as err:  # a name that is neither: no hint
        check_couplings([Coupling.make("att.torque", "adcs.tork")], inputs, outputs)
    assert str(err.value).endswith("has no output 'tork' (outputs: torque)")


def test_a_gain_given_as_a_list_of_numbers_is_told_to_be_a_diagonal_matrix() -> None:
    """k = [1, 1, 1] read "gain of shape (3,) does not apply to a signal of width 3" (a five-subsim probe)."""
    with pytest.raises(CouplingError) as err:
        check_couplings([Coupling.make("b.u", "a.x", "gain", {"k": [1.0, 2.0, 3.0]})], {"b": {"u": 3}, "a": {}},
                        {"a": {"x": 3}, "b": {}})
    assert str(err.value).endswith("a gain is a number or a matrix (a list of rows), got a list of 3 numbers: for one "
                                   "gain per channel give the diagonal matrix [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], "
                                   "[0.0, 0.0, 3.0]]"), err.value
