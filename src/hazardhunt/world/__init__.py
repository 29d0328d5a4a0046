"""The simulated workplace: geometry, floor map, scenarios and kinematics (pure functions)."""
