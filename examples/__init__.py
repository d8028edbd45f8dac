"""Example leg maps shipped with legcal-bench (installed as `legcal_bench.examples`).

`unitree_g1.legmap.yaml` makes the third-party Unitree G1 in `../shared/external` a
legcal-bench robot through its leg map alone; its MJCF is found relative to the leg
map, so outside a checkout with `../shared` beside it the robot is reported missing
and suites skip it.
"""
