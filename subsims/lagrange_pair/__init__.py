"""SRB + parachute on a frictionless swivel (Watts, NASA TP-3220): Lagrange multiplier with drift elimination."""
