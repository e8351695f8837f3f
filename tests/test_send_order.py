"""The coordinator starts the slowest subsim of a run first (longest processing time first).

With more subsims in a run than cores, the run ends when its slowest subsim ends: started first, it has a core at
once. Real processes on loopback: three integrators in a ring coupled by RF-C (all three in every run), the middle
one of the plan's order slowed by ``compute_delay``. The order changes nothing of the results.
"""

from __future__ import annotations

import numpy as np

from cosim.coupler.convergence import Tolerance
from cosim.coupler.couplings import Coupling
from cosim.coupler.relaxation import Interval, Settings
from cosim.driver import Coordinator
from cosim.handles import InProcessHandle, SubsimHandle
from cosim.launch import Bus
from subsims.integrator.subsim import Integrator

RING = [Coupling.make("a.u", "c.y", "gain", {"k": -0.8}), Coupling.make("b.u", "a.y"), Coupling.make("c.u", "b.y")]
PARAMS = {"a": {"y0": [1.0]}, "b": {"y0": [0.5]}, "c": {"y0": [-0.25]}}
DELAY = {"a": 0.0, "b": 0.15, "c": 0.01}  # s each run: b the slowest, by far (kept on a loaded machine)
SETTINGS = Settings(method="centralized", interval=0.1, samples=4, first_guess="extrapolate", interp="cubic",
                    tol=Tolerance(1e-12, 1e-14))


def sends_in_order(handles: dict[str, SubsimHandle]) -> list[str]:
    """The names of the subsims as their run_interval requests are sent, in order (the handles are wrapped)."""
    sent: list[str] = []
    for name, handle in handles.items():
        start = handle.start_run_interval

        def recording(*args, _start=start, _name=name, **kwargs):  # type: ignore[no-untyped-def]
            sent.append(_name)
            return _start(*args, **kwargs)

        handle.start_run_interval = recording  # type: ignore[method-assign]
    return sent


def run(handles: dict[str, SubsimHandle], intervals: int) -> tuple[list[str], list[Interval]]:
    for name, handle in handles.items():
        handle.configure({"size": 1, "compute_delay": DELAY[name], **PARAMS[name]})
    sent = sends_in_order(handles)
    got: list[Interval] = []
    Coordinator(handles, RING, SETTINGS).run(0.0, intervals * 0.1, on_interval=got.append)
    return sent, got


def test_the_slowest_subsim_is_sent_first_once_it_has_been_waited_for(cosim_bus: Bus) -> None:
    remote = {name: cosim_bus.spawn("subsims.integrator", f"order-{name}", quiet=True).handle for name in "abc"}
    sent, got = run(remote, 3)
    runs = [sent[i:i + 3] for i in range(0, len(sent), 3)]
    assert len(runs) >= 6 and all(sorted(r) == ["a", "b", "c"] for r in runs)
    assert runs[0] == ["a", "b", "c"]  # nothing measured yet: the plan's order
    # b's reply came last, so every later run starts with b. (a and c, answered by then, are not timed: a wait
    # that did not block says nothing of them; timed anyway, they would look as slow as b and take turns first.)
    assert all(r[0] == "b" for r in runs[1:]), runs
    # in one process nothing is waited for: the plan's order throughout, and the same bits
    local_sent, local = run({name: InProcessHandle(Integrator(), name) for name in "abc"}, 3)
    assert local_sent == ["a", "b", "c"] * (len(local_sent) // 3)
    assert len(got) == len(local) == 3
    for x, y in zip(got, local):
        for name in "abc":
            np.testing.assert_array_equal(x.outputs[name]["y"], y.outputs[name]["y"])
