"""The control layer under `envs/` and `evaluation/`: the batched arm simulator (sim.py), the PD baseline and its gain
rule (pd.py, pd_gains.py), the closed loop and its policies (loop.py), a robot record's reaching control defaults
(robot_defaults.py) and goal poses the camera sees (targets.py). It imports neither envs, evaluation nor training:
the environments and the benchmarks both stand on it, as dm_control's suite stands on its physics."""
