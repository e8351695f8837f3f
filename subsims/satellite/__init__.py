"""The satellite of Nixon, "System Simulation by Recursive Feedback" (NASA/TP-2001-211331).

Three subsystems, each a stand-alone subsim: ``subsims.orbit`` (point-mass orbit), ``subsims.attitude``
(rigid-body attitude and control) and ``subsims.aero`` (six-facet box aerodynamics). This package holds
what they share: ``constants`` (spec §7), the vectorised coupling
``transforms``, the unified reference ``unified.run_unified`` (RK-U) and the paper's ``cases``.
Spec: /work/shared/specs/recursive-feedback-satellite.md.
"""
