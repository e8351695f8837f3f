"""A coupling plan: the couplings checked once against the subsims' ports, with the execution order.

Built once per run, after every subsim has described its ports; the relaxation machine and every
driver trust it and check nothing again.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property

from cosim.coupler.couplings import Coupling, Ports, SignalRef, check_couplings
from cosim.coupler.order import check_order, derive_order, feedback_weight, is_feedback


@dataclass(frozen=True)
class Plan:
    names: tuple[str, ...]  # every subsim, in declared order
    inputs: Mapping[str, Mapping[str, int]]  # subsim -> input port -> width
    outputs: Mapping[str, Mapping[str, int]]  # subsim -> output port -> width
    couplings: tuple[Coupling, ...]
    order: tuple[str, ...]  # the distributed method's execution order (declared order for centralized)
    feedback: tuple[Coupling, ...]  # couplings with a source at or after their target in ``order``
    forward: tuple[Coupling, ...]
    held: Mapping[str, tuple[float, ...]] = field(default_factory=dict)  # "subsim.port" -> constant; else zero
    guess: Mapping[str, tuple[float, ...]] = field(default_factory=dict)  # "subsim.port" -> its value before any
    # is known (stage 0 of the first interval, every stage 0 with first_guess = "zero"); else zero

    @property
    def sizes(self) -> dict[SignalRef, int]:
        return {SignalRef(s, p): w for s, ports in self.inputs.items() for p, w in ports.items()}

    @cached_property
    def forward_into(self) -> dict[str, tuple[Coupling, ...]]:
        """Per subsim, the forward couplings that drive its inputs (from subsims before it in ``order``)."""
        return {name: tuple(c for c in self.forward if c.target.subsim == name) for name in self.order}

    @cached_property
    def levels(self) -> tuple[tuple[str, ...], ...]:
        """``order`` grouped into levels: a subsim's level is one past the highest level of the subsims its
        forward couplings read (0 when it reads none). The subsims of a level read nothing of each other in
        the current stage, so they can run concurrently and still see exactly what they see run one after
        the other in ``order`` (multicolour Gauss-Seidel: an alternating chain is two levels, not N)."""
        level: dict[str, int] = {}
        for name in self.order:
            reads = {s.subsim for c in self.forward_into[name] for s in c.sources}
            level[name] = 1 + max((level[r] for r in reads), default=-1)
        return tuple(tuple(n for n in self.order if level[n] == k) for k in range(max(level.values(), default=-1) + 1))

    @property
    def feedback_signals(self) -> int:
        """Scalar signals crossing the recursive transfer point in ``order``."""
        return feedback_weight(self.order, self.couplings, self.sizes)

    @classmethod
    def build(
        cls,
        inputs: Ports,
        outputs: Ports,
        couplings: Sequence[Coupling],
        method: str = "centralized",
        order: Sequence[str] | None = None,
    ) -> Plan:
        """Check ``couplings`` (``CouplingError`` names the first bad one) and fix the order.

        ``order`` (distributed only) must name every subsim once; None derives the lightest one.
        """
        names = tuple(inputs)
        if set(outputs) != set(names):
            raise ValueError(f"inputs and outputs describe different subsims: {sorted(inputs)}, {sorted(outputs)}")
        check_couplings(couplings, inputs, outputs)
        sizes = {SignalRef(s, p): w for s, ports in inputs.items() for p, w in ports.items()}
        if order is not None:  # a scenario's order was checked when it was parsed; this is for direct callers
            chosen = check_order(order, names)
        elif method == "distributed":
            chosen = tuple(derive_order(names, couplings, sizes))
        else:
            chosen = names
        rank = {n: i for i, n in enumerate(chosen)}
        return cls(
            names,
            {s: dict(p) for s, p in inputs.items()},
            {s: dict(p) for s, p in outputs.items()},
            tuple(couplings),
            chosen,
            tuple(c for c in couplings if is_feedback(c, rank)),
            tuple(c for c in couplings if not is_feedback(c, rank)),
        )
