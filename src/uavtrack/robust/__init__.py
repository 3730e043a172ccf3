"""The robustness mechanisms of the cycle (`config.RobustModel`): `gate`, the
measurement-consistency gate a fused estimate must pass before it replaces a UAV's own
(``robust.gate``), and `plausibility`, the bounds a value in a message must lie within
for an honest member to have sent it (what the agents admit from their peers).
"""
