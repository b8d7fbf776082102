"""charctl.sim: the MuJoCo humanoid (humanoid.py), its batched simulator (batch.py), the shared scene.

The defaults every simulation uses are stated here once (light: no mujoco import):
- PHYSICS_HZ, the MuJoCo step rate. scripts/bench_sim.py --sweep: with JOINT_ARMATURE 0.01, 120-150 Hz
  blow up and >= 240 Hz is stable; with 0.05, 120-150 Hz are stable too (cgail's small preset runs
  150 Hz with 0.05). DeepMimic steps at 1200 Hz.
- JOINT_ARMATURE, the rotor inertia added to every hinge (kg m^2).
- CONTROL_HZ, the policy rate (DeepMimic's 30 Hz); PD targets are held over PHYSICS_HZ / CONTROL_HZ
  physics substeps.
"""

PHYSICS_HZ = 300.0
JOINT_ARMATURE = 0.01
CONTROL_HZ = 30.0
