"""The distributed method's execution order: the fewest feedback signals (a minimum feedback arc set).

A coupling is feedback when some source runs at or after its target (a self-coupling always is); its
weight is the width of the target signal. Finding the lightest order is NP-hard in general, so:

- up to ``EXACT_LIMIT`` subsims, exact: dynamic programming over the sets of subsims already placed
  (2^n sets, not n! orders); ties go to the order closest to the declared one (lexicographically
  smallest in declared positions);
- beyond, a heuristic: the Eades-Lin-Smyth greedy order (sinks last, sources first, otherwise the
  subsim with the largest outgoing-minus-incoming weight first), then single-subsim moves to any
  other position while one lowers the weight.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from cosim.coupler.couplings import Coupling, SignalRef

EXACT_LIMIT = 12


def check_order(order: Any, names: Sequence[str]) -> tuple[str, ...]:
    """``order`` as a tuple if it names every subsim in ``names`` exactly once; ValueError otherwise."""
    if not isinstance(order, (list, tuple)) or sorted(map(str, order)) != sorted(names) or len(order) != len(names):
        raise ValueError(f"order {order!r} must name every subsim exactly once: {list(names)}")
    return tuple(order)


def feedback_weight(order: Sequence[str], couplings: Sequence[Coupling], sizes: Mapping[SignalRef, int]) -> int:
    """Scalar signals that cross the recursive transfer point when subsims run in ``order``."""
    rank = {name: i for i, name in enumerate(order)}
    return sum(sizes[c.target] for c in couplings if is_feedback(c, rank))


def is_feedback(c: Coupling, rank: Mapping[str, int]) -> bool:
    """A coupling runs backwards when some source runs at or after its target."""
    return any(rank[s.subsim] >= rank[c.target.subsim] for s in c.sources)


def derive_order(names: Sequence[str], couplings: Sequence[Coupling], sizes: Mapping[SignalRef, int]) -> list[str]:
    """The execution order with the fewest feedback signals (see the module docstring)."""
    names = list(names)
    if len(names) <= EXACT_LIMIT:
        return _exact(names, couplings, sizes)
    return _improve(_greedy(names, couplings, sizes), couplings, sizes)


def _exact(names: list[str], couplings: Sequence[Coupling], sizes: Mapping[SignalRef, int]) -> list[str]:
    n = len(names)
    bit = {name: 1 << i for i, name in enumerate(names)}
    # per subsim: (mask of the sources, weight) of each coupling into it
    into: list[list[tuple[int, int]]] = [[] for _ in names]
    for c in couplings:
        mask = 0
        for s in c.sources:
            mask |= bit[s.subsim]
        into[names.index(c.target.subsim)].append((mask, sizes[c.target]))

    def cost(v: int, placed: int) -> int:  # v placed after exactly the subsims in ``placed``
        return sum(w for mask, w in into[v] if mask & ~placed)

    full = (1 << n) - 1
    rest = [0] * (1 << n)  # rest[S]: least weight of ordering the others once S is placed first
    for placed in range(full - 1, -1, -1):
        rest[placed] = min(cost(v, placed) + rest[placed | 1 << v] for v in range(n) if not placed >> v & 1)
    order, placed = [], 0
    while placed != full:
        v = next(v for v in range(n)
                 if not placed >> v & 1 and cost(v, placed) + rest[placed | 1 << v] == rest[placed])
        order.append(names[v])
        placed |= 1 << v
    return order


def _greedy(names: list[str], couplings: Sequence[Coupling], sizes: Mapping[SignalRef, int]) -> list[str]:
    edges = [(s.subsim, c.target.subsim, sizes[c.target]) for c in couplings for s in c.sources
             if s.subsim != c.target.subsim]
    left, head, tail = list(names), [], []
    while left:
        live = set(left)
        out = {v: 0 for v in left}
        inn = {v: 0 for v in left}
        for a, b, w in edges:
            if a in live and b in live:
                out[a] += w
                inn[b] += w
        sink = next((v for v in left if out[v] == 0), None)
        source = next((v for v in left if inn[v] == 0), None)
        if sink is not None:
            tail.insert(0, sink)
            left.remove(sink)
        elif source is not None:
            head.append(source)
            left.remove(source)
        else:
            best = max(left, key=lambda v: out[v] - inn[v])
            head.append(best)
            left.remove(best)
    return head + tail


def _improve(order: list[str], couplings: Sequence[Coupling], sizes: Mapping[SignalRef, int]) -> list[str]:
    weight = feedback_weight(order, couplings, sizes)
    improved = True
    while improved:
        improved = False
        for i in range(len(order)):
            for j in range(len(order)):
                if i == j:
                    continue
                trial = order.copy()
                trial.insert(j, trial.pop(i))
                w = feedback_weight(trial, couplings, sizes)
                if w < weight:
                    order, weight, improved = trial, w, True
    return order
