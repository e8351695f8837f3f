"""Attitude control for the flexbody: a PD law on the report's 1-2-3 Euler angles and body rates, or an open-loop
bang-bang slew (spec AT-10). Output: the torque tau0 at O_g, body axes (the flexbody's ``tau0`` input)."""
