"""Flexible spacecraft, lumped-parameter idealization with modal truncation (Storch & Gates, CSDL-R-1582).

Modules: ``modal`` (constrained modes, chapter 5; spec §2.4 boom stiffness), ``model`` (equations of motion,
chapters 3, 4, 6, 8), ``kinematics`` (chapter 7, attitude held as a quaternion), ``appendage`` (the appendage
alone, spec §4.4-4.5), ``reference`` (monolithic references), ``vehicle`` (the report's appendix-B vehicle as
default parameters), ``config`` (parameter validation), ``outputs``, ``subsim`` (adapter ``FlexBody``).

Co-simulation packagings (spec §4), chosen by the parameter ``mode``:

1. ``mode = "free"`` + ``subsims.flexbody_control`` (flexbody owns the attitude; recommended for the report's
   light bus): flexbody.euler123, flexbody.omega -> control; control.tau0 -> flexbody.tau0. The controller is
   algebraic. Monolithic reference: ``reference.closed_loop_reference(flex_params, control_params, times)``.
2. ``mode = "attitude"`` (spec mode C with inertia split, C2): a rigid attitude subsim owns the rotation of the
   composite undeformed vehicle about its mass centre c0, with inertia J_split = J - D from
   ``appendage.coupling_constants(params)``, and outputs omega and omega_dot (``subsims.attitude`` has both and
   an ``inertia`` parameter). Signals: attitude.omega -> flexbody.omega, attitude.omega_dot ->
   flexbody.omega_dot; flexbody.tau_flex_split -> the attitude's external torque about c0 (summed with any other
   torque; a torque tau0 and force f0 at O_g act about c0 as tau0 - c0 x f0). Without the split (C1) use J and
   flexbody.tau_flex instead (loop gain mu = 0.96 for the report's vehicle: impractical; 0.23 for the heavy bus).
   Body axes of both are parallel; units must agree (the flexbody is unit-agnostic, labels per ``units``).
   Monolithic reference: ``reference.heavy_bus_slew_reference(times)`` (spec AT-13).
3. ``mode = "base"`` (spec mode B): prescribed a_O, omega, omega_dot in; appendage loads on the bus out
   (F_int/T_int for a bus-only simulator, F_flex/T_flex for a composite one). Converges only for a heavy bus.
"""
