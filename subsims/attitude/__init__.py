"""Attitude dynamics and control subsim: rigid body, 3-2-1 Euler angles, gravity gradient (paper §4.2)."""
