"""Flexible spacecraft, lumped-parameter idealization with modal truncation (Storch & Gates, CSDL-R-1582).

Physics: ``modal`` (chapter 5), ``model`` (chapters 3, 4, 6, 8), ``kinematics`` (chapter 7, quaternion-held),
``appendage`` (the appendage alone for coupling to a rigid attitude simulator), ``reference`` (monolithic
references). Parameters: ``vehicle`` (the report's appendix-B vehicle). Adapter: ``subsim.FlexBody``.
"""
