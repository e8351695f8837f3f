"""Recursive-feedback coupling, sans-IO: no transport, no handles, no clock.

- ``couplings``: output signals -> one input signal, through a transform;
- ``order``: the distributed method's execution order (fewest feedback signals);
- ``plan``: the couplings checked once against the subsims' ports, with the order;
- ``convergence``: the paper's ``convrg`` check; ``first_guess``: stage-0 inputs;
- ``relaxation``: the state machine (Jacobi and Gauss-Seidel) that says what to run next.

``cosim.driver`` runs the machine over subsim handles.
"""
