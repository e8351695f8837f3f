"""Double integrator y'' = u of the paper's §2.3 (eq. 6 with coupling -w^2)."""
