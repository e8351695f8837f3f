"""An interrupted run goes on from its latest resume point (``cosim run --resume``), with the same results as a
run that was never interrupted: byte for byte, for both methods, CSV and NPZ, fixed and automatic intervals."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cosim.outputs import OutputError, resume_path
from cosim.results import read_results
from cosim.runner import run_scenario
from cosim.scenario import load, parse

ROOT = Path(__file__).resolve().parents[1]
OSCILLATOR = ROOT / "scenarios" / "oscillator.toml"
AUTO = ROOT / "scenarios" / "satellite" / "case1-auto.toml"


class Stop(Exception):
    """Stands for what interrupts a run (a signal, a crash of the coordinator's machine)."""


def every(path: Path, n: int):
    sc = load(path)
    return parse({**sc.raw, "run": {**sc.raw.get("run", {}), "checkpoint_every": n}}, sc.path)


def stop_after(k: int):
    seen = [0]

    def on_interval(_interval) -> None:
        seen[0] += 1
        if seen[0] == k:
            raise Stop

    return on_interval


@pytest.mark.parametrize(("scenario", "method", "suffix", "stop", "cut"), [
    (OSCILLATOR, "distributed", ".csv", 3.0, 47),  # 60 intervals, stopped at 47, resumed at 40
    (OSCILLATOR, "centralized", ".npz", 3.0, 47),
    (AUTO, "distributed", ".csv", 400.0, 45),  # 68 intervals of its own lengths
])
def test_a_resumed_run_writes_what_an_uninterrupted_one_does(tmp_path: Path, scenario: Path, method: str,
                                                             suffix: str, stop: float, cut: int) -> None:
    sc = every(scenario, 10)
    whole, part = tmp_path / f"whole{suffix}", tmp_path / f"part{suffix}"
    whole_report = run_scenario(sc, method=method, stop=stop, output=whole, inprocess=True, progress=False)
    assert not resume_path(whole).exists()  # a finished run leaves none
    with pytest.raises(Stop):
        run_scenario(sc, method=method, stop=stop, output=part, inprocess=True, progress=False,
                     on_interval=stop_after(cut))
    assert resume_path(part).exists()
    _, cut_data = read_results(part) if suffix == ".csv" else (None, None)
    if suffix == ".csv":  # the units file removed meanwhile: written again (it stayed gone: a red team)
        Path(f"{part}.meta.json").unlink()
    report = run_scenario(sc, method=method, stop=stop, output=part, inprocess=True, progress=False, resume=True)
    assert report.summary.intervals == whole_report.summary.intervals - 40  # from the checkpoint at 40, not 0
    assert not resume_path(part).exists()
    if suffix == ".csv":
        assert part.read_bytes() == whole.read_bytes()
        assert Path(f"{part}.meta.json").read_bytes() == Path(f"{whole}.meta.json").read_bytes()
        assert cut_data is not None and cut_data.shape[0] > 0
    else:
        (cols, a), (cols_b, b) = read_results(whole), read_results(part)
        assert cols == cols_b and np.array_equal(a, b)
    diag = [line.split(",")[:5] for line in Path(f"{part}.diag.csv").read_text().splitlines()]
    assert diag == [line.split(",")[:5] for line in Path(f"{whole}.diag.csv").read_text().splitlines()]


def test_a_resume_point_of_another_scenario_or_none_is_refused(tmp_path: Path) -> None:
    sc = every(OSCILLATOR, 10)
    out = tmp_path / "x.csv"
    with pytest.raises(OutputError, match=r"no resume point .* from the start \(--overwrite instead of --resume\)"):
        run_scenario(sc, stop=2.0, output=out, inprocess=True, progress=False, resume=True)
    with pytest.raises(Stop):
        run_scenario(sc, stop=2.0, output=out, inprocess=True, progress=False, on_interval=stop_after(25))
    changed = parse({**sc.raw, "coupling": {**sc.raw["coupling"], "samples": 6}}, sc.path)
    with pytest.raises(OutputError, match="a resume point of another scenario or method") as err:
        run_scenario(changed, stop=2.0, output=out, inprocess=True, progress=False, resume=True)
    assert "(they must be the same but for stop; changed: coupling.samples: 5 -> 6)" in str(err.value)
    with pytest.raises(OutputError, match="a resume point of another scenario or method") as err:
        run_scenario(sc, method="centralized", stop=2.0, output=out, inprocess=True, progress=False, resume=True)
    assert 'changed: method: "distributed" -> "centralized")' in str(err.value)  # what changed, named
    with pytest.raises(OutputError, match="exists: continue that run with --resume"):
        run_scenario(sc, stop=2.0, output=out, inprocess=True, progress=False, overwrite=False)
    same = parse({**sc.raw, "subsims": {**sc.raw["subsims"], "mass2": {  # u0 = 0 for 0.0: the same scenario
        **sc.raw["subsims"]["mass2"], "params": {**sc.raw["subsims"]["mass2"]["params"], "u0": 0}}}}, sc.path)
    assert sc.raw["subsims"]["mass2"]["params"]["u0"] == 0.0
    report = run_scenario(same, stop=3.0, output=out, inprocess=True, progress=False, resume=True)  # and further
    assert report.summary.t_end == 3.0 and read_results(out)[1][-1, 0] == 3.0


def test_cosim_run_resume_after_sigint_over_zenoh(tmp_path: Path) -> None:
    """End to end over the bus: SIGINT, then the same command with --resume; the CSV is the uninterrupted one."""
    scenario = tmp_path / "osc.toml"
    scenario.write_text(OSCILLATOR.read_text() + "\n[run]\ncheckpoint_every = 20\n")
    cosim = [sys.executable, "-m", "cosim.cli", "run", str(scenario), "--stop", "20", "--quiet"]
    whole, part = tmp_path / "whole.csv", tmp_path / "part.csv"
    assert subprocess.run([*cosim, "--output", str(whole)], capture_output=True, timeout=120).returncode == 0
    proc = subprocess.Popen([*cosim, "--output", str(part)], stderr=subprocess.PIPE, text=True)
    try:
        import time

        deadline = time.monotonic() + 60
        while not resume_path(part).exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        proc.send_signal(2)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if proc.returncode == 0:
        pytest.skip("the run ended before SIGINT reached it")  # pragma: no cover - a 20 s run takes ~1 s
    assert proc.returncode == 130 and "(go on with the same command with --resume)" in err, err
    done = subprocess.run([*cosim, "--output", str(part), "--resume"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert part.read_bytes() == whole.read_bytes()
    import re

    said = re.search(r"\((distributed|centralized)\): (\d+) intervals from its resume point at t = (\d+) to t = 20 in ",
                     done.stdout)
    assert said, done.stdout  # where it went on from, and the intervals it ran from there (20 per resume point)
    assert 0 < int(said[3]) < 20 and int(said[2]) == round((20 - int(said[3])) / 0.05)


def test_a_last_interval_cut_to_end_at_stop_is_no_resume_point(tmp_path: Path) -> None:
    """interval = "auto" cuts its last interval to end at stop; a run going further does not end an interval
    there, so resuming from it with a later stop gave other results. Stopped in that last interval (a resume
    point at every interval), the run resumes from the one before, and matches the longer run."""
    sc = every(AUTO, 1)
    whole, part = tmp_path / "whole.csv", tmp_path / "part.csv"
    run_scenario(sc, stop=600.0, output=whole, inprocess=True, progress=False)

    def at_the_end(interval) -> None:
        if float(interval.t[-1]) == 300.0:
            raise Stop

    with pytest.raises(Stop):
        run_scenario(sc, stop=300.0, output=part, inprocess=True, progress=False, on_interval=at_the_end)
    run_scenario(sc, stop=600.0, output=part, inprocess=True, progress=False, resume=True)
    assert part.read_bytes() == whole.read_bytes()


@pytest.mark.parametrize("damage", ["diag cut", "diag edited", "resume point cut", "results edited", "diag removed"])
def test_damaged_files_are_refused_in_one_line_and_left_as_they_are(tmp_path: Path, damage: str) -> None:
    sc = every(OSCILLATOR, 10)
    out = tmp_path / "x.csv"
    with pytest.raises(Stop):
        run_scenario(sc, stop=3.0, output=out, inprocess=True, progress=False, on_interval=stop_after(47))
    target = {"diag cut": Path(f"{out}.diag.csv"), "diag edited": Path(f"{out}.diag.csv"),
              "resume point cut": resume_path(out), "results edited": out,
              "diag removed": Path(f"{out}.diag.csv")}[damage]
    raw = target.read_bytes()
    lines = raw.splitlines(keepends=True)
    damaged = {"diag cut": b"".join(lines[:20]), "diag edited": b"".join(lines[:10] + [b"abc\n"] + lines[11:]),
               "resume point cut": raw[:1200], "results edited": b"".join(lines[:50] + [b"a,b,c\n"] + lines[51:]),
               "diag removed": b""}
    if damage == "diag removed":  # (it read "not the diagnostics of a cosim run to resume": a red team)
        target.unlink()
    else:
        target.write_bytes(damaged[damage])
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    with pytest.raises(OutputError) as err:
        run_scenario(sc, stop=3.0, output=out, inprocess=True, progress=False, resume=True)
    assert "\n" not in str(err.value) and ("run it again" in str(err.value) or "cannot resume" in str(err.value))
    assert damage != "diag removed" or "is missing (removed since the run stopped)" in str(err.value), err.value
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


@pytest.mark.parametrize("edit", ["state one ulp", "coupler signal removed", "point's time"])
def test_a_resume_point_edited_into_another_valid_one_is_refused(tmp_path: Path, edit: str) -> None:
    """A resume point rewritten with a state one ulp off, or a coupler signal left out, was resumed from without a
    word, and the results differed from an uninterrupted run's (a red team); its time changed blamed the CSV."""
    sc = every(OSCILLATOR, 10)
    out = tmp_path / "x.csv"
    with pytest.raises(Stop):
        run_scenario(sc, stop=3.0, output=out, inprocess=True, progress=False, on_interval=stop_after(47))
    point = resume_path(out)
    with np.load(point) as z:
        arrays = {k: z[k] for k in z.files}
    if edit == "state one ulp":
        arrays["state/mass1"] = np.nextafter(arrays["state/mass1"], np.inf)
    elif edit == "coupler signal removed":
        name = next(k for k in arrays if k.startswith("previous/"))
        del arrays[name], arrays[name.replace("previous/", "previous_t/")]
    else:
        import json

        meta = json.loads(bytes(arrays["meta"]).decode())
        meta["t"] = 1.0
        arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    with open(point, "wb") as f:
        np.savez(f, **arrays)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    with pytest.raises(OutputError) as err:
        run_scenario(sc, stop=3.0, output=out, inprocess=True, progress=False, resume=True)
    assert str(err.value) == f"{point} is not as its run saved it (its contents do not match the SHA-256 saved with " \
                             "them: edited or damaged since): run it again from the start with --overwrite"
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_an_atomic_write_cut_short_leaves_nothing_for_long(tmp_path: Path) -> None:
    """A SIGKILL while a resume point (or an NPZ) was being written left ``.<file>.tmp-<pid>`` for good: the next run
    on that output, holding its lock, removes them."""
    out = tmp_path / "x.csv"
    stale = tmp_path / ".x.csv.resume.npz.tmp-99999"
    stale.write_bytes(b"half")
    other = tmp_path / ".y.csv.resume.npz.tmp-99999"  # another output's: not this run's to remove
    other.write_bytes(b"half")
    longer = tmp_path / ".x.csv.2.csv.diag.csv.staged.tmp-99999"  # x.csv.2.csv's, a run that may be going on: its
    longer.write_bytes(b"live")  # staged diagnostics were removed and it stopped (durability probe)
    staged = tmp_path / ".x.csv.diag.csv.staged.tmp-99999"
    staged.write_bytes(b"half")
    run_scenario(every(OSCILLATOR, 10), stop=0.5, output=out, inprocess=True, progress=False)
    assert not stale.exists() and not staged.exists() and other.exists() and longer.exists()


def test_proving_a_file_writable_never_leaves_an_empty_file_under_its_name(tmp_path: Path, monkeypatch) -> None:
    """A SIGKILL between creating a result's name (to prove it could) and removing it left an empty x.csv ('exists:
    pass --overwrite') or x.csv.resume.npz ('continue that run with --resume', then 'damaged')."""
    from cosim import outputs

    def killed(path):  # noqa: ANN001, ANN202
        raise KeyboardInterrupt  # the process dies here

    monkeypatch.setattr(outputs.os, "unlink", killed)
    for name in ("x.csv", "x.csv.resume.npz"):
        with pytest.raises(KeyboardInterrupt):
            outputs.probe_writable(tmp_path / name)
        assert not (tmp_path / name).exists()


def _delete_line(lines: list[bytes]) -> list[bytes]:
    return lines[:10] + lines[11:]


def _duplicate_line(lines: list[bytes]) -> list[bytes]:
    return lines[:10] + [lines[10]] + lines[10:]


def _change_a_value(lines: list[bytes], column: int = 1) -> list[bytes]:
    fields = lines[10].split(b",")
    fields[column] = repr(float(fields[column]) + 0.5).encode()
    return lines[:10] + [b",".join(fields)] + lines[11:]


@pytest.mark.parametrize(("which", "edit"), [
    ("results", _delete_line), ("results", _duplicate_line), ("results", _change_a_value),
    ("diagnostics", lambda lines: _change_a_value(lines, column=5)),  # a wall time: nothing else looks at it
])
def test_results_edited_before_the_resume_point_are_not_resumed_from(tmp_path: Path, which: str, edit) -> None:
    """A row deleted, duplicated or changed before the resume point went on silently (one row fewer or more, or the
    changed value, in a run that said it was whole; ops probe): the resume point holds the size and SHA-256 of what
    the run had written up to it, and the files must still hold exactly that."""
    sc = every(OSCILLATOR, 10)
    part = tmp_path / "part.csv"
    with pytest.raises(Stop):
        run_scenario(sc, stop=3.0, output=part, inprocess=True, progress=False, on_interval=stop_after(47))
    edited = part if which == "results" else part.with_name(part.name + ".diag.csv")
    original = edited.read_bytes()
    changed = b"".join(edit(original.splitlines(keepends=True)))  # line 10: before the resume point at t = 2
    assert changed != original
    edited.write_bytes(changed)
    with pytest.raises(OutputError) as err:
        run_scenario(sc, stop=3.0, output=part, inprocess=True, progress=False, resume=True)
    assert str(err.value) == (f"{edited} is not as the run left it up to its resume point at t = 2 (rows removed, "
                              "added or changed since): it cannot go on from there; run it again from the start with "
                              "--overwrite")
    assert edited.read_bytes() == changed  # refused before anything was cut or written
    edited.write_bytes(original)
    run_scenario(sc, stop=3.0, output=part, inprocess=True, progress=False, resume=True)  # as the run left them


def test_a_resume_point_without_the_files_hashes_says_that_edits_are_not_found(tmp_path: Path) -> None:
    """A resume point saved by the cosim before the hashes went on silently unchecked (red team): it goes on, and
    says so."""
    from dataclasses import replace

    from cosim.resume import load as load_resume
    from cosim.resume import save as save_resume

    sc = every(OSCILLATOR, 10)
    part = tmp_path / "part.csv"
    with pytest.raises(Stop):
        run_scenario(sc, stop=3.0, output=part, inprocess=True, progress=False, on_interval=stop_after(47))
    saved = load_resume(resume_path(part))
    assert saved.written is not None
    save_resume(resume_path(part), replace(saved, written=None))
    said: list[str] = []
    run_scenario(sc, stop=3.0, output=part, inprocess=True, progress=False, resume=True, log=said.append)
    assert said == [f"cosim: the resume point at t = 2 was saved by an earlier cosim, without the sizes and hashes of "
                    f"{part} and its diagnostics: edits to them since are not found"]


def stopped_and_resumed_once(sc, part: Path) -> list[str]:
    """Run ``sc`` to its 47th interval (a resume point every 10), resume it and stop it 5 intervals on: what that
    resume said."""
    with pytest.raises(Stop):
        run_scenario(sc, stop=3.0, output=part, inprocess=True, progress=False, on_interval=stop_after(47))
    said: list[str] = []
    with pytest.raises(Stop):
        run_scenario(sc, stop=3.0, output=part, inprocess=True, progress=False, resume=True, log=said.append,
                     on_interval=stop_after(5))
    return said


def test_a_resume_with_another_file_a_parameter_names_goes_on_and_says_so(tmp_path: Path, monkeypatch) -> None:
    """An FMU rebuilt between the stop and the resume: the run went on with the other model and said nothing (FMI
    probe). Going on is right (fixing a model is a reason to resume), unnoticed is not."""
    import cosim.runner
    from cosim.resume import model_files

    fmu = tmp_path / "m.fmu"  # a file a parameter names (params.fmu, as fmu = "m.fmu" makes it)
    fmu.write_bytes(b"one build")
    digests = model_files({"a": {"fmu": str(fmu), "k": 1.0, "name": "not a file", "doc": "x" * 5000, "nul": "a\0b"}})
    assert list(digests) == [str(fmu)]
    monkeypatch.setattr(cosim.runner, "model_files", lambda params: model_files({"a": {"fmu": str(fmu)}}))
    sc = every(OSCILLATOR, 10)
    part = tmp_path / "part.csv"
    said = stopped_and_resumed_once(sc, part)
    assert said == []  # the same file
    fmu.write_bytes(b"another build")
    run_scenario(sc, stop=3.0, output=part, inprocess=True, progress=False, resume=True, log=said.append)
    assert said == [f"cosim: {fmu} is not the file the run had when its resume point at t = 2 was saved: the "
                    "results before that point came from the earlier one"]


def test_a_resume_with_other_model_code_goes_on_and_says_which_module_changed(tmp_path: Path) -> None:
    """A model's helper module edited between the stop and the resume (a newcomer probe: the results jumped at the
    resume point, nothing said; a parameter changed in the scenario is refused, so resume looked guarded). Going on
    is right (fixing a model is a reason to resume); unnoticed is not."""
    (tmp_path / "resumehelper.py").write_text("SCALE = 1.0\n")
    (tmp_path / "resumemass.py").write_text("import resumehelper  # noqa: F401\n"
                                            "from subsims.oscillator.subsim import Mass as _Mass\n\n\n"
                                            "class Mass(_Mass):\n    pass\n")
    text = OSCILLATOR.read_text().replace('"subsims.oscillator.subsim:Mass"', '"resumemass:Mass"')
    (tmp_path / "s.toml").write_text(text)
    sc = every(tmp_path / "s.toml", 10)
    part = tmp_path / "part.csv"
    said = stopped_and_resumed_once(sc, part)
    assert said == []  # the same code
    (tmp_path / "resumehelper.py").write_text("SCALE = 2.0\n")
    run_scenario(sc, stop=3.0, output=part, inprocess=True, progress=False, resume=True, log=said.append)
    assert said == [f"cosim: {name}'s code is not what the run had when its resume point at t = 2 was saved "
                    "(resumehelper changed since): the results before that point came from the earlier code"
                    for name in ("mass1", "mass2")]


def test_what_changed_since_a_resume_point_is_shown_short_and_exact() -> None:
    """(red team) a long path changed after its 57th character, and 0.0 to -0.0, showed no change at all; a removed
    key showed as the string '(none)'; one edit in a long list printed the whole list."""
    from cosim.resume import changes

    path = "/data/models/of/the/vehicle/for/this/study/version-2026-11/mass2.fmu"
    assert changes({"p": path, "z": 0.0, "r": 1.0, "g": list(range(5000))},
                   {"p": path.replace("mass2", "mass3"), "z": -0.0, "g": [*range(4999), 7]}) == [
        "g[4999]: 4999 -> 7",
        'p: "/data/models/of/the/vehicle...dy/version-2026-11/mass2.fmu" -> "/data/models/of/the/vehicle...'
        'dy/version-2026-11/mass3.fmu"',
        "r: 1 -> (absent)", "z: 0 -> -0.0"]
    couplings = [{"to": "a.u", "from": ["b.y"]}, {"to": "b.u", "from": ["a.y"]}]
    assert changes({"couplings": couplings}, {"couplings": couplings[:1]}) == [  # which one (it said 2 -> 1 only)
        'couplings: 2 -> 1 items; removed {"from": ["a.y"], "to": "b.u"}']
    assert changes({"g": [1.0, 2.0]}, {"g": [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]}) == ["g: 2 -> 6 items; added 3, 4, 5, ..."]


@pytest.mark.parametrize("edited", ["results", "diagnostics"])
def test_an_npz_edited_since_its_run_stopped_is_refused_as_a_csv_is(tmp_path: Path, edited: str) -> None:
    """A stopped run builds its NPZ; the resume streams it again and skipped the check of both files against the resume
    point, so an NPZ whose row 10 was changed (or a diagnostics row) resumed and kept the change (durability probe)."""
    sc = every(OSCILLATOR, 10)
    part = tmp_path / "p.npz"
    with pytest.raises(Stop):
        run_scenario(sc, method="centralized", stop=3.0, output=part, inprocess=True, progress=False,
                     on_interval=stop_after(47))
    if edited == "results":
        with np.load(part) as z:
            arrays = {k: z[k] for k in z.files}
        arrays["data"][10, 1] += 1000.0
        np.savez(part, **arrays)
    else:
        diag = Path(f"{part}.diag.csv")
        lines = diag.read_text().splitlines()
        fields = lines[5].split(",")
        fields[3] = str(int(fields[3]) + 1)  # the stages of interval 5
        lines[5] = ",".join(fields)
        diag.write_text("\n".join(lines) + "\n")
    with pytest.raises(OutputError, match=r"is not as the run left it up to its resume point at t = 2"):
        run_scenario(sc, method="centralized", stop=3.0, output=part, inprocess=True, progress=False, resume=True)
