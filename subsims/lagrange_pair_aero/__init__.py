"""The SRB + parachute aerodynamics of Watts (NASA TP-3220) as a separate algebraic subsim."""
