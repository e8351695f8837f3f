"""The ``cosim`` command: run and describe scenarios, serve a subsim, plot results."""

from __future__ import annotations

import argparse
import errno
import math
import os
import shlex
import signal
import sys
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from cosim import __version__, interrupt
from cosim.console import say
from cosim.contract import PROTOCOL_VERSION, SubsimError
from cosim.coupler.couplings import TransformError
from cosim.coupler.relaxation import METHODS, Interval, NotConverged, Settings
from cosim.outputs import OutputError, OutputWriteError, diag_path, is_npz, resume_path, stream_path
from cosim.preflight import UsageError, check_listen, check_run_options, check_stop, zenoh_error_line
from cosim.protocol.keys import check_name
from cosim.protocol.security import Security
from cosim.protocol.transport.session import BusError
from cosim.resume import load as load_resume
from cosim.runner import default_output, open_session, run_scenario
from cosim.scenario import ScenarioError, load

# what `cosim run` runs with no scenario: the paper's satellite, case 1, RF-D over Zenoh, shortened
DEFAULT_SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "satellite" / "case1.toml"
DEFAULT_STOP = 3000.0  # about a minute over Zenoh


def _run(args: argparse.Namespace) -> int:
    """``cosim run``. SIGINT, SIGTERM and SIGHUP stop it cleanly: the subsims are stopped, every committed
    interval is in the results, one line says where it stopped, and the exit status is 128 + the signal."""
    state: dict = {"t": None, "output": args.output}
    try:
        with interrupt.handling():
            status = _run_until_done(args, state)
            late = interrupt.late()
        if late is not None:
            say(f"cosim: {late} came after the run had finished; nothing was cut short")
        return status
    except (SubsimError, NotConverged, TransformError, OutputWriteError) as exc:  # said by main(), with this note
        if state["t"] is not None and state["output"] is not None:
            point = _resume_time(Path(state["output"]))
            kept = _kept(Path(state["output"]))
            if kept is not None and _at_stop(state):
                # every interval is in: only the results' last step failed (an NPZ built from its stream); a resume
                # point would be refused, "nothing to resume" (a red team)
                _drop_resume_point(Path(state["output"]))
                exc.add_note(f"every interval to t = {state['t']:.6g} s, the run's stop, is in {kept}: nothing is "
                             "left to run")
            elif point is not None and kept is not None:  # (a results file removed meanwhile is not there to go on)
                exc.add_note(f"every interval to t = {state['t']:.6g} s is in {kept}; once that is fixed, the same "
                             f"command {_with_resume(args)} goes on from t = {point:.6g} s")
            elif kept is not None:  # no resume point yet: the same command alone would refuse the file it left
                again = "the same command" if args.overwrite else "the same command with --overwrite"
                exc.add_note(f"every interval to t = {state['t']:.6g} s is in {kept}; once that is fixed, {again} "
                             "runs it again from the start")
        raise
    except interrupt.Interrupted as exc:
        t = state["t"]
        if _at_stop(state):  # only its end was left
            _drop_resume_point(Path(state["output"]))  # (its subsims' last commit): it is whole
            say(f"cosim: {exc.name} came as the run finished; every interval to t = {t:.6g} s is in {state['output']}")
            _summary(f"results: {state['output']}\ndiagnostics: {diag_path(Path(state['output']))}")  # as a run's end
            return 0
        if state["t"] is None:
            where = "before any new interval was committed" if args.resume else "before any interval was committed"
        else:
            kept = _kept(Path(state["output"]))
            where = f"at t = {state['t']:.6g} s" + (f"; every committed interval is in {kept}" if kept else "")
        if state["output"] is not None and resume_path(Path(state["output"])).exists():
            where += f" (go on with the same command {_with_resume(args)})"
        say(f"cosim: stopped by {exc.name} {where}")  # (its terminal may be gone: the status still says it)
        return exc.exit_status


def _at_stop(state: dict) -> bool:
    """Whether the run's committed intervals reach its stop (``state``: its last committed time and its stop)."""
    t, stop = state["t"], state.get("stop")
    return t is not None and stop is not None and t >= stop - 1e-9 * max(1.0, abs(stop))


def _drop_resume_point(output: Path) -> None:
    """Remove the resume point of a run whose every interval is in; one a read-only directory keeps is left (the
    line said about the run is what matters, not a traceback)."""
    try:
        resume_path(output).unlink(missing_ok=True)
    except OSError:
        pass


def _summary(text: str) -> None:
    """A finished run's summary on stdout. When its terminal went away (EIO: closed under a run that ignores SIGHUP)
    it is dropped: the run got to its end, and its files say the rest."""
    try:
        print(text, flush=True)
    except OSError as exc:
        if exc.errno != errno.EIO:  # (a closed pipe: 141, in main)
            raise
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nothing left to fail at exit


def _with_resume(args: argparse.Namespace) -> str:
    return "with --resume instead of --overwrite" if args.overwrite else "with --resume"


def _kept(output: Path) -> str | None:
    """Where a stopped run's intervals are: its results file, or the samples an NPZ could not be built from yet (a
    full disk) with how to build it; None when neither is there (removed during the run)."""
    if output.exists():
        return str(output)
    if is_npz(output) and stream_path(output).exists():
        return f"{stream_path(output)} (`cosim recover {output}` builds the NPZ from it)"
    return None


def _resume_time(output: Path) -> float | None:
    """The time of the resume point a stopped run left beside ``output``, if it left one that reads."""
    try:
        return load_resume(resume_path(output)).point.t
    except OutputError:
        return None


def _run_until_done(args: argparse.Namespace, state: dict) -> int:
    if args.scenario is None:
        if not DEFAULT_SCENARIO.exists():
            raise ScenarioError(f"no scenario given and the default {DEFAULT_SCENARIO} is not there (installed "
                                "without the source tree?): name a scenario file")
        args.scenario = DEFAULT_SCENARIO
        args.stop = DEFAULT_STOP if args.stop is None else args.stop
        print(f"cosim: no scenario given: running {DEFAULT_SCENARIO} to t = {args.stop:g} s "
              f"(the full paper run: cosim run scenarios/satellite/case1.toml)", file=sys.stderr)
        args.plot = True
    scenario = load(args.scenario)
    check_stop(args.stop, scenario.start)
    check_run_options(args)
    state["stop"] = scenario.stop if args.stop is None else args.stop
    method = args.method or scenario.default_method
    output = state["output"] = Path(args.output) if args.output is not None else default_output(scenario, method)

    def committed(interval: Interval) -> None:
        state["t"] = float(interval.t[-1])

    if args.resume and args.overwrite:
        raise UsageError("--resume goes on with the results; --overwrite starts them again: give one of them")
    if method == "unified":
        from cosim.unified import run_unified

        if args.resume:
            raise UsageError("--resume continues coupled runs (centralized, distributed), not unified ones")
        report = run_unified(scenario, stop=args.stop, output=output, overwrite=args.overwrite, on_interval=committed)
    else:
        security = _security(args, scenario.security)
        if args.inprocess and scenario.run.timeout is not None:  # (the file serves both ways: said, not refused)
            say(f"cosim: [run] timeout = {scenario.run.timeout:g} s is for subsim processes: with --inprocess nothing "
                "times out a model (Ctrl-C stops one in Python code)")
        if not args.inprocess:
            if args.listen is not None:
                check_listen(args.listen)
            launched = any(not spec.external for spec in scenario.subsims.values())
            if security is not None and security.tls and security.tls_ca is None and launched:
                raise UsageError("with --tls-cert the subsims cosim launches need --tls-ca too: the CA that signed "
                                 "the certificate, to verify the router with (they would time out)")
        report = run_scenario(scenario, method=method, stop=args.stop, output=output, inprocess=args.inprocess,
                              listen=args.listen, progress=not args.quiet, on_interval=committed,
                              overwrite=args.overwrite, restarts=args.restarts, timeout=args.timeout,
                              security=security, run_id=args.run_id, attach_wait=args.attach_wait,
                              resume=args.resume)
    s = report.summary
    hist = ", ".join(f"{v} took {k} stage{'s' if k != 1 else ''}" for k, v in sorted(s.stages.items()))
    resumed = f" from its resume point at t = {s.t_start:.6g}" if args.resume else ""
    plural = "s" if s.intervals != 1 else ""
    lines = [f"{scenario.name} ({report.method}): {s.intervals} interval{plural}{resumed} to t = {s.t_end:.6g} in "
             f"{s.wall_time:.2f} s{f' ({hist})' if hist else ''}"]
    if report.method != "unified" and s.intervals:  # what the run cost in requests (rejected tries included)
        span = s.t_end - s.t_start
        per_second = f" ({s.round_trips / span:.3g} round trips per simulated second)" if span > 0 else ""
        took = "" if args.inprocess or s.round_trip_median is None else \
            f"; a round trip took {_duration(s.round_trip_median)} (median), {_duration(s.round_trip_max)} at most"
        lines.append(f"requests: {s.requests / s.intervals:.2f} an interval, sent in "
                     f"{s.round_trips / s.intervals:.2f} round trips{per_second}{took}")
    if s.converged_last:  # which checked signals (outputs in RF-C, fed-back inputs in RF-D) the iteration waits for
        slowest = ", ".join(f"{name} in {count}" for name, count in s.converged_last.most_common(3))  # most first
        more = f" (and {len(s.converged_last) - 3} more signals)" if len(s.converged_last) > 3 else ""
        last = s.converged_last.most_common(3)[-1][1]
        lines.append(f"slowest to converge (failed the check before the last): {slowest} "
                     f"interval{'s' if last != 1 else ''}{more}")
    if s.rejected:  # tries rolled back and run again shorter: their cost is in the wall time, not the histogram
        why = (f"{s.unconverged} not converged, {s.rejected - s.unconverged} over interval_tol"
               if scenario.settings_for(report.method).auto is not None else "not converged: max_halvings")
        lines.append(f"rejected: {s.rejected} tries, retried shorter ({why}), {s.rejected_stages} stages run in them")
    if s.over_tol:
        lines.append(f"over interval_tol: {s.over_tol} intervals, accepted at interval_min (their error column in "
                     "the diagnostics says by how much)")
    for r in report.extra.get("restarts", []):
        done = ("started again" if math.isnan(r.at) else f"restored to t = {r.at:g}") if r.restored else \
            "the replacement failed while being restored"
        lines.append(f"restart: {r.subsim} {r.reason}; {done}")
    if report.method == "distributed":
        lines.append(f"order: {' -> '.join(report.order)}; feedback: {'; '.join(report.feedback) or 'none'}")
    lines.append(f"results: {report.output}\ndiagnostics: {report.diagnostics}")
    _summary("\n".join(lines))
    if args.plot:
        from cosim.plot import plot_files

        pngs = plot_files([report.output], report.output.parent / "plots")
        _summary(f"plots: {', '.join(str(p) for p in pngs)}")
    return 0


def _duration(seconds: float | None) -> str:
    """``0.52 ms``, ``9.1 s``: a round trip's time as an operator reads it."""
    if seconds is None:
        return "?"
    return f"{_figure(1e3 * seconds)} ms" if seconds < 1.0 else f"{_figure(seconds)} s"


def _figure(x: float) -> str:
    """Two significant digits, never in exponent form (230, not 2.3e+02: a newcomer probe)."""
    shown = f"{x:.2g}"
    return f"{x:.0f}" if "e" in shown else shown  # (99.7 rounds to 1e+02 too)


def _recover(args: argparse.Namespace) -> int:
    from cosim.results import recover

    print(recover(args.path))
    return 0


def _security(args: argparse.Namespace, default: Security | None) -> Security | None:
    """--tls-*/--auth-file/--mutual-tls replace the scenario's [security] table when any is given."""
    # absolute: subsims started in another directory (a launcher's workdir) are given the same paths
    given = {k: Path(getattr(args, k)).absolute() for k in ("tls_cert", "tls_key", "tls_ca", "auth_file")
             if getattr(args, k)}
    if not given and not args.mutual_tls:
        return default
    try:
        return Security(**given, mutual=args.mutual_tls).check()
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None


def _ports(ports: dict) -> str:
    return ", ".join(f"{p}({port.size}{' ' + port.unit if port.unit else ''})" for p, port in ports.items())


def _describe(args: argparse.Namespace) -> int:
    scenario = load(args.scenario)
    print(f"{scenario.name}: {scenario.description}".rstrip(": "))
    print(f"time: {scenario.start:g} to {scenario.stop:g}")
    if args.listen is not None:
        if not args.launch:
            raise UsageError("--listen is where the router of --launch listens: give --launch too")
        check_listen(args.listen)
    shown = scenario
    if not args.launch:  # a subsim served elsewhere is described from its model here, where the scenario names one
        here = {n: replace(s, external=False, launcher=()) for n, s in scenario.subsims.items()
                if (s.external or s.launcher) and s.model is not None}
        shown = replace(scenario, subsims={**scenario.subsims, **here})
    session = open_session(shown, inprocess=not args.launch, listen=args.listen,
                           log=lambda m: print(m, file=sys.stderr))
    try:
        print("subsims:")
        for name, d in session.descriptions.items():
            ins, outs = _ports(d.inputs), _ports(d.outputs)
            spec = scenario.subsims[name]
            kind = f"{spec.model}, external" if spec.external and spec.model else spec.model or "external"
            if spec.launcher:
                kind += f", started with {shlex.join(spec.launcher)}"
            print(f"  {name} [{kind}]{' algebraic' if d.algebraic else ''}\n    in:  {ins or '-'}\n    out: {outs}")
            given = scenario.subsims[name].params
            for k, p in d.params.items():  # the model's declared parameters: the value used, unit, meaning
                value = f"{given[k]!r}" if k in given else f"{p.default!r} (default)"
                print(f"    param {k} = {value}{' ' + p.unit if p.unit else ''}{': ' + p.doc if p.doc else ''}")
        print("couplings:")
        for c in scenario.couplings:
            extra = f" via {c.transform_name}" if c.transform_name != "identity" else ""
            params = ", ".join(f"{k} = {v!r}" for k, v in c.params.items())  # (a gain's value, a lever arm)
            print(f"  {c}{extra}{f' ({params})' if params else ''}")
        held = session.plans[scenario.default_method].held
        if held:
            print(f"held inputs: {'; '.join(f'{k} = {list(v)}' for k, v in held.items())}")
        for method in METHODS:
            st = scenario.settings_for(method)
            print(f"{method}: {_interval_text(st)}, {st.samples} samples, tol {st.tol.rel:g}/{st.tol.abs:g}, "
                  f"first guess {st.first_guess}, interp {st.interp}, at most {st.max_stages} stages"
                  + (f", {st.max_halvings} halvings" if st.max_halvings else "")
                  + (", speculate" if st.speculate and method == "distributed" else ""))
            if method == "distributed":
                plan = session.plans[method]
                given = "given" if st.order is not None else "derived"
                print(f"  order ({given}): {' -> '.join(plan.order)}")
                if len(plan.levels) < len(plan.order):  # some subsims run side by side
                    groups = " -> ".join("{" + ", ".join(level) + "}" if len(level) > 1 else level[0]
                                         for level in plan.levels)
                    print(f"  run as {len(plan.levels)} concurrent groups per stage: {groups}")
                print(f"  feedback edges ({plan.feedback_signals} scalar signals): "
                      f"{'; '.join(map(str, plan.feedback)) or 'none'}")
    finally:
        session.close()
    return 0


def _interval_text(settings: Settings) -> str:
    auto = settings.auto
    if auto is None:
        return f"H = {settings.interval:g}"
    return (f"H = auto from {auto.initial:g} in [{auto.minimum:g}, {auto.maximum:g}], interval_tol {auto.tol:g}, "
            f"grows below {auto.stages} stages")


def _serve(args: argparse.Namespace) -> int:
    from cosim.serve import main as serve

    return serve([args.model, *args.rest])


def _plot(args: argparse.Namespace) -> int:
    from cosim.plot import plot_command

    return plot_command(args)


def _run_id(text: str) -> str:
    try:
        return check_name(text, "--run-id")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cosim", description=__doc__)
    p.add_argument("--version", action="version", version=f"cosim {__version__} (protocol {PROTOCOL_VERSION})")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("run", help="run a scenario")
    r.add_argument("scenario", type=Path, nargs="?",
                   help=f"scenario file (default: {DEFAULT_SCENARIO.name} to t = {DEFAULT_STOP:g} s, with plots)")
    r.add_argument("--plot", action="store_true", help="also write PNG plots beside the results")
    r.add_argument("--stop", type=float, help="stop time (default: the scenario's)")
    r.add_argument("--output", type=Path,
                   help="result file, .csv or .npz (default: results/<name>-<method>.csv)")
    r.add_argument("--overwrite", action="store_true", help="replace an existing result file (default: refuse)")
    r.add_argument("--resume", action="store_true",
                   help="go on with the interrupted run that wrote --output (the same scenario and method; --stop "
                        "may be later), from its latest resume point (one every [run] checkpoint_every intervals)")
    r.add_argument("--method", choices=[*METHODS, "unified"], help="coupling method (default: the scenario's)")
    r.add_argument("--inprocess", action="store_true", help="run every subsim in this process (no Zenoh)")
    r.add_argument("--listen",
                   help="router endpoint (default: a Unix socket only you can reach; tcp/127.0.0.1:0 with external "
                        "subsims, tls/localhost:0 with --tls-cert; use tcp/0.0.0.0:7447 for other machines)")
    r.add_argument("--run-id", type=_run_id, help="run id that namespaces every key (default: a fresh one)")
    r.add_argument("--attach-wait", type=float, default=300.0, metavar="S",
                   help="seconds to wait for the external subsims, all started at once (default: 300)")
    r.add_argument("--quiet", action="store_true",
                   help="no progress display, and the subsims started do not announce themselves")
    r.add_argument("--restarts", type=int, metavar="N",
                   help="replace subsims that die or hang up to N times, restoring their committed state "
                        "(default: the scenario's [run] restarts, 2; 0 stops the run at the first failure)")
    r.add_argument("--timeout", type=float, metavar="SECONDS",
                   help="wait this long for a reply before a subsim counts as hung (default: derived from the "
                        "measured request times, at least 1.5 s, or 10 s with a subsim on another machine)")
    r.add_argument("--tls-cert", type=Path, help="router certificate (PEM); listen on tls/<host>:<port> (see "
                   "docs/reliability.md)")
    r.add_argument("--tls-key", type=Path, help="private key of --tls-cert (PEM)")
    r.add_argument("--tls-ca", type=Path, help="CA certificate that signed --tls-cert (given to launched subsims)")
    r.add_argument("--mutual-tls", action="store_true", help="subsims must present certificates signed by --tls-ca")
    r.add_argument("--auth-file", type=Path, help="'user:password' lines that may log in to the router")
    r.set_defaults(fn=_run)

    d = sub.add_parser("describe", help="print subsims, couplings, execution order and feedback edges")
    d.add_argument("scenario", type=Path)
    d.add_argument("--launch", action="store_true", help="ask real processes (default: in-process models)")
    d.add_argument("--listen", metavar="ENDPOINT",
                   help="with --launch: router endpoint (needed by subsims with a launcher, as for cosim run)")
    d.set_defaults(fn=_describe)

    s = sub.add_parser("serve", help="serve a subsim class as a process (see python -m cosim.serve)")
    s.add_argument("model", help="package.module:Class")
    s.add_argument("rest", nargs=argparse.REMAINDER, metavar="OPTIONS", help="--connect ENDPOINT --run RUN [--name "
                   "NAME] (python -m cosim.serve --help)")
    s.set_defaults(fn=_serve)

    pl = sub.add_parser("plot", help="plot result files to PNG")
    pl.add_argument("results", nargs="+", type=Path, help="result files (.csv/.npz)")
    pl.add_argument("--out", type=Path, default=Path("plots"), help="directory for the PNGs")
    pl.add_argument("--signals", nargs="*", help="columns or signal prefixes to plot (default: all)")
    pl.add_argument("--window", nargs=2, type=float, metavar=("T0", "T1"),
                    help="plot only this time span (the paper's figs. 8-16: --window 40000 60000)")
    pl.set_defaults(fn=_plot)

    rc = sub.add_parser("recover", help="make a result file whole after its coordinator was killed",
                        description="NPZ: build it from the samples streamed to PATH.partial. CSV: cut a partial "
                                    "last row. Refused while a run writes PATH.")
    rc.add_argument("path", type=Path, help="the result file (.csv or .npz) the killed run was writing")
    rc.set_defaults(fn=_recover)
    for command in sub.choices.values():  # its own usage for a mistake in its arguments, not the top-level one
        command.set_defaults(parser=command)
    return p


def main(argv: Sequence[str] | None = None, parsed: Callable[[], None] | None = None) -> int:
    """``parsed``: called once the arguments are read, before the command does anything (``cosim.command`` hands
    the signals back to Python's defaults there)."""
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:
        args.parser.error(f"unrecognized arguments: {' '.join(extra)}")
    if parsed is not None:
        parsed()
    try:
        status = args.fn(args)
        sys.stdout.flush()  # a closed pipe shows here, not at exit
        return status
    except BrokenPipeError:  # `cosim describe X | head -1`: the reader has what it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 141  # 128 + SIGPIPE, as a program killed by the signal
    except OutputWriteError as exc:  # the run stopped; its files end at the last whole interval
        if args.fn is _recover:  # (no run to stop: "run stopped" read oddly of cosim recover on a full disk)
            say(f"cosim: {exc}")
        else:
            _say_stopped(exc)
        return 1
    except (ScenarioError, OutputError, UsageError) as exc:
        say(f"cosim: {exc}")
        return 2
    except BusError as exc:
        line = zenoh_error_line(exc, getattr(args, "listen", None) or "")
        say(f"cosim: {line}")
        return 2 if line.startswith("--listen") else 1
    except (NotConverged, TransformError) as exc:
        _say_stopped(exc)
        return 1
    except SubsimError as exc:
        _say_stopped(exc)
        if exc.traceback:  # a bug in a model: its own frames, file and line, as the subsim saw them
            say(f"the model's traceback (in subsim {exc.subsim!r}):\n{exc.traceback.rstrip()}")
        return 1
    except KeyboardInterrupt:
        say("cosim: interrupted; results up to the last committed interval are kept")
        return 130


def _say_stopped(exc: Exception) -> None:
    say(f"cosim: run stopped: {exc}")
    for note in getattr(exc, "__notes__", ()):
        say(f"cosim: {note}")


def entry(parsed: Callable[[], None] | None = None) -> int:
    """The ``cosim`` command: :func:`main`, then nothing a signal could change about the exit status (a SIGTERM
    in the last milliseconds of a finished run killed it, rc -15, its files whole)."""
    status = main(parsed=parsed)
    for s in interrupt.SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    return status


if __name__ == "__main__":
    raise SystemExit(entry())
