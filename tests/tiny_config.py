"""The tiny configuration of the tests' ``tactile run``: every step, on coarse meshes and short chains (the loop
and the robust recommendation off: they are tested in test_loop.py and test_robust_recommendation.py)."""

TINY = """
[design]
ceramic_thicknesses_mm = [1.0]
[maps]
grid = 9
fem_grid = 2
fem_ceramic_thicknesses_mm = [1.0]
[fem]
accuracy = 0.05
survey_accuracy = 0.0
elements_per_ceramic = 2
elements_per_layer = 1
elements_across_half_width = 3
width_points = 3
fine_width_min_mm = 48.0
fine_width_max_mm = 50.0
[campaign]
voltages_v = [5.0, 15.0]
points_per_sweep = 21
ringdown_voltages_v = [5.0, 15.0]
ringdown_samples = 40
[damping]
laws = ["quadratic"]
walkers = 32
max_steps = 1500
posterior_draws = 8
[loop]
enabled = false
[recommendation]
robust = false
"""
"""A run of about a minute that passes through every step."""
