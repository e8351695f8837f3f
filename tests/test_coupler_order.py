"""The distributed execution order: exact where cheap, checked against brute force over all orders."""

from __future__ import annotations

import itertools
import random

import pytest

from cosim.coupler.couplings import Coupling
from cosim.coupler.order import EXACT_LIMIT, check_order, derive_order, feedback_weight


def random_system(rng: random.Random, n: int) -> tuple[list[str], list[Coupling], dict]:
    names = [f"s{i}" for i in range(n)]
    couplings, sizes = [], {}
    for target in names:
        for port in range(rng.randint(0, 2)):
            sources = rng.sample(names, rng.randint(1, min(3, n)))
            c = Coupling.make(f"{target}.in{port}", [f"{s}.out" for s in sources], "linear",
                              {"gains": [1.0] * len(sources)})
            couplings.append(c)
            sizes[c.target] = rng.choice([1, 1, 2, 3, 6])
    return names, couplings, sizes


@pytest.mark.parametrize("seed", range(40))
def test_exact_order_has_the_brute_force_minimum_and_its_tie_break(seed: int) -> None:
    """Against every permutation (the first in declared-position order among the lightest)."""
    rng = random.Random(seed)
    names, couplings, sizes = random_system(rng, rng.randint(2, 6))
    brute = min(itertools.permutations(names), key=lambda p: feedback_weight(p, couplings, sizes))
    assert derive_order(names, couplings, sizes) == list(brute)


def chain(n: int) -> tuple[list[str], list[Coupling], dict]:
    """Masses in a row, each driven by its neighbours (the benchmark's N-mass chain)."""
    names = [f"m{i}" for i in range(n)]
    couplings = []
    for i in range(n):
        srcs = [f"m{j}.x" for j in (i - 1, i + 1) if 0 <= j < n]
        couplings.append(Coupling.make(f"m{i}.f", srcs, "linear", {"gains": [1.0] * len(srcs)}))
    return names, couplings, {c.target: 1 for c in couplings}


@pytest.mark.parametrize("n", [4, 8, EXACT_LIMIT, EXACT_LIMIT + 4, 31])
def test_a_chain_needs_feedback_into_every_other_mass_only(n: int) -> None:
    """Every adjacent pair needs one of its two masses fed back: a minimum vertex cover of a path, n // 2."""
    names, couplings, sizes = chain(n)
    assert feedback_weight(derive_order(names, couplings, sizes), couplings, sizes) == n // 2
    # the declared (in-line) order is far from it
    assert feedback_weight(names, couplings, sizes) == n - 1


def test_check_order_names_what_is_wrong() -> None:
    assert check_order(["b", "a"], ["a", "b"]) == ("b", "a")
    for bad in (["a"], ["a", "a"], ["a", "b", "c"], "ab", None):
        with pytest.raises(ValueError, match="every subsim exactly once"):
            check_order(bad, ["a", "b"])
