"""charctl: training and evaluation toolkit for physics-based and data-driven character animation."""

import os as _os

__version__ = "0.1.0"

# MuJoCo picks its OpenGL backend when it is first imported: on a machine without a display
# default to OSMesa (software, Debian's libosmesa6) so offscreen rendering works headless.
if not _os.environ.get("DISPLAY") and "MUJOCO_GL" not in _os.environ:
    _os.environ["MUJOCO_GL"] = "osmesa"
# OpenMP threads (torch) busy-wait by default, which wastes the few cores of a shared or small
# machine while MuJoCo's batch threads work; passive waiting costs nothing measurable here.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
if _os.environ.get("MUJOCO_GL") == "osmesa":
    _os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
