"""charctl.sim: the MuJoCo humanoid (humanoid.py), its batched simulator (batch.py), the shared scene.

The two rates every simulation defaults to are stated here once (light: no mujoco import):
PHYSICS_HZ, the MuJoCo step rate (scripts/bench_sim.py --sweep: 120 Hz blows up, >= 240 Hz is stable;
DeepMimic steps at 1200 Hz), and CONTROL_HZ, the policy rate (DeepMimic's 30 Hz); PD targets are held
over PHYSICS_HZ / CONTROL_HZ physics substeps.
"""

PHYSICS_HZ = 300.0
CONTROL_HZ = 30.0
