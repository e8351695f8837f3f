"""One mass of a spring-mass chain: m u'' = -k u + F, with F the force of the cut springs.

Two of these, cut at the middle spring, are the two-mass three-spring coupling benchmark
(scenarios/oscillator.toml): m1 = m2 = 1, k1 = k2 = 4 pi^2, k12 = 16 pi^2, u(0) = (1, 0), v(0) = 0,
exact u1,2 = 1/2 cos 2 pi t +- 1/2 cos 6 pi t.
"""
