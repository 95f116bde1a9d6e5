"""Everything MuJoCo and motion data: Acclaim I/O, humanoid model, retargeting, velocities,
replay checks and rendering. Submodules that need MuJoCo import it themselves."""

import os

# Offscreen rendering: EGL (Mesa's llvmpipe without a GPU) unless the user chose another backend.
os.environ.setdefault("MUJOCO_GL", "egl")
