"""The FMU subsim on one FMU, in process: ports, configure, CS and ME stepping, state, refusals.

Expected values are closed-form solutions of the test FMU's model, m u'' = -k u + F (conftest builds it
from scenarios/fmu/csrc), never outputs of the code under test.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.contract import CosimError
from cosim.runtime import Runtime
from cosim.subsim import ModelError
from subsims.fmu import FmuSubsim
from subsims.fmu.fmu import FmuError, read_fmu
from subsims.fmu.subsim import MAGIC, decode_state, encode_state

M, KS = 2.0, 50.0  # a mass and spring different from every default
W = np.sqrt(KS / M)


def forced(t: np.ndarray, u0: float, v0: float, a: float, b: float) -> np.ndarray:
    """Closed form of m u'' + k u = a + b t: particular (a + b t) / k plus the free oscillation."""
    return (a + b * t) / KS + (u0 - a / KS) * np.cos(W * t) + (v0 - b / KS) / W * np.sin(W * t)


def configured(path: Path, **params) -> Runtime:
    rt = Runtime(FmuSubsim)
    rt.configure({"fmu": str(path), "m": M, "k": KS, **params}, 0.0)
    return rt


def run(rt: Runtime, t: np.ndarray, force: np.ndarray, commit: bool = False) -> dict:
    return rt.run_interval(t, {"F": force.reshape(-1, 1)}, commit=commit)


def python_m(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "subsims.fmu", *args], capture_output=True, text=True,
                          timeout=60, env=dict(os.environ))


@pytest.mark.parametrize("version", [2, 3])
def test_ports_and_metadata_come_from_the_model_description(fmus: dict[str, Path], version: int) -> None:
    desc = Runtime(FmuSubsim(fmus[f"mass{version}"])).describe()  # before configure: the path was given
    assert desc["inputs"] == {"F": {"size": 1, "unit": "N", "doc": "external force on the mass"}}
    assert desc["outputs"] == {"u": {"size": 1, "unit": "m", "doc": "displacement"},
                               "v": {"size": 1, "unit": "m/s", "doc": "velocity"}}
    done = python_m(str(fmus[f"mass{version}"]), "--describe")
    assert done.returncode == 0, done.stderr
    meta = json.loads(done.stdout)
    assert meta["fmi_version"] == f"{version}.0"
    assert meta["interfaces"] == ["cs", "me"]
    assert meta["can_save_state"] == {"cs": True, "me": True}
    assert meta["parameters"] == {"m": "1", "k": "39.47841760435743", "u0": "0", "v0": "0"}
    assert meta["inputs"] == {"F": "N"} and meta["outputs"] == {"u": "m", "v": "m/s"}


@pytest.mark.parametrize(
    ("params", "phrase"),
    [
        ({"mass": 1.0}, "unknown FMU variable(s) ['mass'] in mass2.fmu; settable: k, m, u0, v0"),
        ({"v_0": 1.0}, "unknown FMU variable(s) ['v_0'] in mass2.fmu (did you mean 'v0'?); settable: k, m, "),
        # the hint named the wrong one first ('v_0' for 'v0'), and an output was a typo for a start value
        ({"v_0": 1.0, "kk": 2.0}, "unknown FMU variable(s) ['kk', 'v_0'] in mass2.fmu (did you mean 'k' for 'kk', "
                                  "'v0' for 'v_0'?)"),
        ({"u": 1.0}, "['u'] in mass2.fmu is an output, which the FMU computes: not a parameter; settable: k, m, "),
        ({"u": 1.0, "zz": 2}, "['u'] in mass2.fmu is an output, which the FMU computes: not a parameter; unknown too: "
                              "['zz']; settable: k, m, "),
        ({"F": 1.0}, "['F'] in mass2.fmu is a real input: a port, fed by a coupling or held constant in the "
                     "scenario's [subsims.<name>.inputs] (F = [value]), not a parameter"),
        ({"m": "heavy"}, "m is Real: needs a finite number, got 'heavy'"),
        ({"m": True}, "m is Real: needs a finite number, got True"),
        ({"interface": "scheduled"}, "interface 'scheduled' not available in mass2.fmu; it offers 'cs', 'me'"),
        ({"substeps": 0}, "substeps must be a positive integer, got 0"),
        # a setting of the other interface did nothing (an FMI probe)
        ({"rtol": 1e-6, "max_step": 0.1}, "max_step, rtol: model-exchange setting(s), and mass2.fmu runs as "
                                          "co-simulation (interface = 'cs'), stepped by its own solver"),
        ({"interface": "me", "substeps": 4}, "substeps: a co-simulation setting, and mass2.fmu runs as model "
                                             "exchange (interface = 'me'), integrated by solve_ivp"),
        # Float32 states under model exchange at the default rtol: 142 s for a 1 s run at 1e-10, 2.1 s at 1e-6
        ({"fmu": "mass3_f32", "interface": "me"}, "mass3_f32.fmu: its state(s) v are Float32 (about 7 digits), so "
                                                  "model exchange cannot meet rtol = 1e-10 (the default)"),
        ({"fmu": "mass3_f32", "interface": "me", "rtol": 1e-7}, "cannot meet rtol = 1e-07: the solver grinds"),
        ({"values": {"m": 2.0}}, "['m'] given both in params and in params.values"),
        ({"k": -1.0}, "initialization failed: ExitInitializationMode: fmi2ExitInitializationMode failed with status "
                      "3 (error): m and k must be positive"),
    ],
)
def test_configure_refuses_bad_parameters_in_one_line(fmus: dict[str, Path], params: dict, phrase: str) -> None:
    rt = Runtime(FmuSubsim)
    params = dict(params)
    fmu = str(fmus[params.pop("fmu", "mass2")])  # (a test FMU by its name)
    with pytest.raises(CosimError) as err:
        rt.configure({"fmu": fmu, "m": M, **params})
    assert err.value.code == "bad_value"
    assert phrase in err.value.message and "\n" not in err.value.message
    assert rt.state is None  # nothing configured


@pytest.mark.parametrize("version", [2, 3])
def test_cosimulation_with_constant_force_is_exact(fmus: dict[str, Path], version: int) -> None:
    """The FMU steps exactly for a force held over the step, so a constant force leaves no error at all:
    this checks parameters, start values, stepping, outputs at the sample times and commit."""
    rt = configured(fmus[f"mass{version}"], u0=0.3, v0=-1.0)
    a, out = 7.0, []
    for i in range(4):
        t = np.linspace(0.1 * i, 0.1 * (i + 1), 6)
        r = run(rt, t, np.full(6, a), commit=i > 0)
        out.append((t, r["outputs"]["u"][:, 0]))
    for t, u in out:
        np.testing.assert_allclose(u, forced(t, 0.3, -1.0, a, 0.0), rtol=0, atol=1e-13)


@pytest.mark.parametrize("kind", ["cs", "me"])
def test_float32_ports_are_read_and_written_as_float32(fmus: dict[str, Path], kind: str) -> None:
    """FMI 3 Float32 variables need fmi3Get/SetFloat32: the test FMU's v and F are Float32 and its Float64
    calls refuse them, as a strict FMU does. A force of 7 N is exact in float32, so u (Float64) must match
    the closed form as the all-Float64 FMU does, and v to float32's precision."""
    rt = configured(fmus["mass3_f32"], interface=kind, u0=0.3, v0=-1.0, **({"rtol": 1e-6} if kind == "me" else {}))
    t = np.linspace(0.0, 0.4, 5)
    out = run(rt, t, np.full(5, 7.0))["outputs"]
    np.testing.assert_allclose(out["u"][:, 0], forced(t, 0.3, -1.0, 7.0, 0.0), rtol=0, atol=1e-7)
    v = -(0.3 - 7.0 / KS) * W * np.sin(W * t) - 1.0 * np.cos(W * t)  # d/dt of forced()
    np.testing.assert_allclose(out["v"][:, 0], v, rtol=0, atol=1e-5)
    assert np.all(out["v"][:, 0] == out["v"][:, 0].astype(np.float32))  # it came through a float32
    # a force beyond float32's range: the FMU's F would be inf, and its outputs were blamed (an FMI probe)
    with pytest.raises(CosimError) as err:
        run(configured(fmus["mass3_f32"], interface=kind, **({"rtol": 1e-6} if kind == "me" else {})), t,
            np.array([7.0, 7.0, 1e39, 7.0, 7.0]))
    said = err.value.message  # (model exchange meets it between the samples, on the interpolated force)
    assert err.value.code == "model_error" and said.startswith("at t in [0.0, 0.4]: input F = ") and said.endswith(
        "is beyond the largest Float32 (3.403e+38), the type of that FMU input"), said
    assert kind == "me" or "input F = 1e+39 at t = 0.2 " in said, said


@pytest.mark.parametrize("version", [2, 3])
def test_model_exchange_reads_inputs_between_samples(fmus: dict[str, Path], version: int) -> None:
    """A ramp force is represented exactly by linear interpolation of its samples, so the ME subsim (scipy
    DOP853 at rtol 1e-10) must match the closed form to solver accuracy. Holding each sample over the step,
    as co-simulation does, is off by about b h / (2 k) = 5e-3 here."""
    rt = configured(fmus[f"mass{version}"], interface="me", u0=0.5)
    a, b = 1.0, 40.0
    t = np.linspace(0.0, 0.5, 11)
    u = run(rt, t, a + b * t)["outputs"]["u"][:, 0]
    np.testing.assert_allclose(u, forced(t, 0.5, 0.0, a, b), rtol=0, atol=1e-8)


def test_model_exchange_sets_a_discrete_input_in_event_mode_once_an_interval(
        fmus: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """FMI lets model exchange set a discrete input only at instantiation, in initialization or event mode: every
    right-hand side set it, and the Reference FMUs' Feedthrough refused ('can only be set ... in event mode'), so no
    ME FMU with a discrete input could run (an FMI probe). Here the mass's F is declared discrete and the rule is
    enforced on the FMU's calls: F is set once, in event mode, at the interval's start, and held (a ramp of force
    acts as its first sample)."""
    import zipfile

    from subsims.fmu.fmu import FmiCallError, Instance

    with zipfile.ZipFile(fmus["mass2"]) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    xml = members["modelDescription.xml"].decode()
    head = xml.index('<ScalarVariable name="F"')
    tag = xml[head:xml.index(">", head) + 1]
    assert 'variability="continuous"' in tag
    members["modelDescription.xml"] = xml.replace(tag, tag.replace('variability="continuous"',
                                                                   'variability="discrete"')).encode()
    discrete = tmp_path / "discrete.fmu"
    with zipfile.ZipFile(discrete, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    f_vr = next(v.vr for v in read_fmu(discrete).inputs if v.name == "F")
    in_event_mode, set_reals, set_in_event_mode = [False], Instance.set_reals, Instance.set_in_event_mode

    def guarded_set(self, ports, values):
        if f_vr in ports.vrs and not in_event_mode[0]:
            raise FmiCallError("fmi2SetReal: F can only be set in initialization or event mode")
        set_reals(self, ports, values)

    def event_mode(self, ports, values):
        in_event_mode[0] = True
        try:
            return set_in_event_mode(self, ports, values)
        finally:
            in_event_mode[0] = False

    monkeypatch.setattr(Instance, "set_reals", guarded_set)
    monkeypatch.setattr(Instance, "set_in_event_mode", event_mode)
    rt = configured(discrete, interface="me", u0=0.5)
    t = np.linspace(0.0, 0.5, 11)
    u = run(rt, t, 1.0 + 40.0 * t)["outputs"]["u"][:, 0]
    np.testing.assert_allclose(u, forced(t, 0.5, 0.0, 1.0, 0.0), rtol=0, atol=1e-8)  # F held at its t = 0 value


def test_model_exchange_asks_after_every_integrator_step_whether_the_fmu_wants_an_event(fmus: dict[str, Path]) -> None:
    """fmi2CompletedIntegratorStep after each accepted step (FMI 2.0, 3.2.2): an FMU asking for event mode from
    t = 0.25 on is refused at the step that got there, not at the interval's end (t = 0.4, as before)."""
    rt = configured(fmus["mass2_step_event"], interface="me", u0=0.5)
    t = np.linspace(0.0, 0.4, 9)
    with pytest.raises(CosimError) as err:
        run(rt, t, np.zeros(9))
    assert err.value.code == "model_error" and "(a step event)" in err.value.message, err.value.message
    at = float(err.value.message.split("event handling at t=")[1].split(" ")[0])
    assert 0.25 <= at < 0.4, err.value.message
    ok = configured(fmus["mass2"], interface="me", u0=0.5)  # the same FMU without the event runs through
    assert run(ok, t, np.zeros(9))["outputs"]["u"].shape == (9, 1)


def test_cosimulation_substeps_shrink_the_hold_error(fmus: dict[str, Path]) -> None:
    """Holding the force over each communication step is first order in the step: eight communication
    steps per sample interval (inputs from the interpolated segment) must cut the error about eightfold."""
    t = np.linspace(0.0, 0.5, 11)
    a, b = 0.0, 40.0
    exact = forced(t, 0.0, 0.0, a, b)
    errors = {}
    for m in (1, 8):
        u = run(configured(fmus["mass2"], substeps=m), t, a + b * t)["outputs"]["u"][:, 0]
        errors[m] = np.abs(u - exact).max()
    assert 6.0 < errors[1] / errors[8] < 10.0, errors


@pytest.mark.parametrize("kind", ["cs", "me"])
def test_advance_is_pure_so_rollback_and_reruns_repeat(fmus: dict[str, Path], kind: str) -> None:
    rt = configured(fmus["mass3"], interface=kind, u0=1.0)
    t = np.linspace(0.0, 0.2, 5)
    first = run(rt, t, np.full(5, 2.0))["outputs"]
    run(rt, t, np.full(5, -30.0))  # another trial from the same committed state
    again = run(rt, t, np.full(5, 2.0))["outputs"]
    for name in first:
        assert np.array_equal(first[name], again[name])
    rt.commit()
    t2 = t + 0.2
    after = run(rt, t2, np.full(5, 2.0))["outputs"]
    rt.commit()
    rt.rollback(0.2)
    redo = run(rt, t2, np.full(5, 2.0))["outputs"]
    assert np.array_equal(after["u"], redo["u"]) and np.array_equal(after["v"], redo["v"])


def test_state_moves_to_a_fresh_runtime(fmus: dict[str, Path]) -> None:
    """get_state / set_state carry the serialized FMU: a restarted subsim continues bit for bit."""
    rt = configured(fmus["mass2"], u0=1.0)
    t = np.linspace(0.0, 0.1, 5)
    run(rt, t, np.full(5, 3.0))
    rt.commit()
    saved = rt.get_state()
    fresh = configured(fmus["mass2"])  # other start values: the state must overwrite them
    fresh.set_state(saved["time"], saved["state"])
    t2 = t + 0.1
    a = run(rt, t2, np.full(5, 3.0))["outputs"]["u"]
    b = run(fresh, t2, np.full(5, 3.0))["outputs"]["u"]
    assert np.array_equal(a, b)
    np.testing.assert_allclose(a[:, 0], forced(t2, 1.0, 0.0, 3.0, 0.0), atol=1e-13)


def test_a_state_vector_that_is_not_an_fmu_state_is_a_model_error(fmus: dict[str, Path]) -> None:
    rt = configured(fmus["mass2"])
    bad = rt.state.copy()
    bad[0] += 1.0
    rt.set_state(0.0, bad)
    with pytest.raises(CosimError) as err:
        run(rt, np.linspace(0, 0.1, 3), np.zeros(3))
    assert err.value.code == "model_error" and "wrong marker" in err.value.message


def test_state_encoding_round_trips_any_bytes_as_finite_floats() -> None:
    rng = np.random.default_rng(7)
    for data in (b"", b"\xff" * 13, bytes(rng.integers(0, 256, 1001, dtype=np.uint8)), b"\x00\x00\xf0\x7f" * 9):
        vec = encode_state(data, 1200)
        assert vec[0] == MAGIC and vec.size == 2 + 200 and np.isfinite(vec).all()
        assert decode_state(vec) == data
    with pytest.raises(ModelError, match="more than the 12 reserved"):
        encode_state(b"x" * 13, 12)
    vec = encode_state(b"abc", 12)
    vec[3] = 0.5
    with pytest.raises(ValueError, match="not the integers"):
        decode_state(vec)
    vec = encode_state(b"abc", 12)
    vec[1] = 13.0
    with pytest.raises(ValueError, match="does not fit"):
        decode_state(vec)


@pytest.mark.parametrize("version", [2, 3])
def test_an_fmu_that_cannot_serialize_its_state_is_refused(fmus: dict[str, Path], version: int) -> None:
    flag = "canSerializeFMUstate" if version == 2 else "canSerializeFMUState"
    path = fmus[f"mass{version}_nostate"]
    with pytest.raises(CosimError) as err:
        Runtime(FmuSubsim).configure({"fmu": str(path)})
    assert f"the FMU cannot serialize its state ({flag} is false for co-simulation)" in err.value.message
    done = python_m(str(path), "--connect", "tcp/127.0.0.1:9", "--run", "r1")  # refused before connecting
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and flag in done.stderr


@pytest.mark.parametrize(
    ("which", "phrase"),
    [
        ("not_zip", "not an FMU (not a zip archive)"),
        ("no_description", "not an FMU (no modelDescription.xml in the archive)"),
        ("bad_description", "invalid modelDescription.xml"),
        ("no_binary", "the FMU has no binaries (binaries/"),
        ("other_platform", "no binary for this platform (binaries/"),
        ("missing", "no such FMU file"),
    ],
)
def test_a_broken_fmu_is_one_clear_line(fmus: dict[str, Path], tmp_path: Path, which: str, phrase: str) -> None:
    path = fmus.get(which, tmp_path / "missing.fmu")
    with pytest.raises(FmuError) as err:
        read_fmu(path)
    assert phrase in str(err.value) and str(path) in str(err.value) and "\n" not in str(err.value)
    if which == "other_platform":
        assert "the FMU has binaries for win64" in str(err.value)
    done = python_m(str(path), "--describe")
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr == f"subsims.fmu: {err.value}\n"
    with pytest.raises(CosimError) as cerr:
        Runtime(FmuSubsim).configure({"fmu": str(path)})
    assert cerr.value.code == "bad_value" and phrase in cerr.value.message
    if which == "missing":  # e.g. `cosim.serve subsims.fmu:FmuSubsim` on another machine, given the coordinator's path
        assert "no such FMU file on this machine" in cerr.value.message
        assert "python -m subsims.fmu /local/path/missing.fmu --connect" in cerr.value.message


def test_describe_loads_the_binary_and_takes_no_other_options(fmus: dict[str, Path]) -> None:
    """--describe said all was well for an FMU whose binary cannot load (the run failed later); and with
    other options after it, it printed the serving usage, never naming --describe."""
    bad = fmus["bad_binary"]
    read_fmu(bad)  # the description and the file list are fine
    done = python_m(str(bad), "--describe")
    assert done.returncode == 2 and done.stdout == "" and done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith(f"subsims.fmu: {bad}: cannot load the binary of its 'cs' interface ("), done.stderr
    done = python_m(str(fmus["mass2"]), "--describe", "--name", "x")
    assert done.returncode == 2 and "--describe takes no other options, got --describe --name x" in done.stderr


def test_bad_fmu_does_not_crash_a_served_subsim(fmus: dict[str, Path], cosim_bus) -> None:
    """Over the bus: configure with a broken FMU is an error reply; the process keeps serving and then
    configures a good one."""
    handle = cosim_bus.spawn("", "fmu", model="subsims.fmu:FmuSubsim").handle
    from cosim.contract import SubsimError

    with pytest.raises(SubsimError) as err:
        handle.configure({"fmu": str(fmus["other_platform"])})
    assert "no binary for this platform" in err.value.message
    desc = handle.configure({"fmu": str(fmus["mass2"]), "u0": 1.0})
    assert list(desc.outputs) == ["u", "v"]


@pytest.mark.slow
def test_python_m_subsims_fmu_serves_the_fmu_given_on_the_command_line(fmus: dict[str, Path], cosim_bus) -> None:
    """``python -m subsims.fmu mass3.fmu --connect EP --run RUN --name m1``: the ports are known before
    configure, and configure needs no ``fmu`` parameter."""
    cmd = [sys.executable, "-m", "subsims.fmu", str(fmus["mass3"]), "--connect", cosim_bus.endpoint,
           "--run", cosim_bus.run, "--name", "m1"]
    proc = subprocess.Popen(cmd, env={**os.environ, **cosim_bus.subsim_env("m1")})  # its key and the login
    handle = None
    try:
        handle = cosim_bus.attach("m1", timeout=30.0, wait=30.0)
        desc = handle.describe()
        assert list(desc.inputs) == ["F"] and desc.outputs["u"].unit == "m"
        handle.configure({"m": M, "k": KS, "u0": 0.25})
        t = np.linspace(0.0, 0.1, 5)
        out = handle.run_interval(t, {"F": np.full((5, 1), 4.0)}).outputs["u"][:, 0]
        np.testing.assert_allclose(out, forced(t, 0.25, 0.0, 4.0, 0.0), atol=1e-13)
        handle.shutdown()
        assert proc.wait(20) == 0
    finally:
        if handle is not None:
            handle.close()
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def test_a_subsim_started_with_its_fmu_serves_that_file(fmus: dict[str, Path]) -> None:
    """An external subsim started as ``python -m subsims.fmu /here/mass2.fmu`` is configured with the
    coordinator's path of the same file: the name must match, the directory is the subsim's own."""
    rt = Runtime(FmuSubsim(fmus["mass2"]))
    rt.configure({"fmu": "/on/the/coordinator/mass2.fmu", "u0": 1.0})
    assert rt.model.info.path == fmus["mass2"].resolve()
    with pytest.raises(CosimError) as err:
        rt.configure({"fmu": str(fmus["mass3"])})
    assert "this subsim serves mass2.fmu (given when it started); params.fmu names mass3.fmu" in err.value.message
