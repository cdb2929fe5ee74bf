"""Evaluation of domain translation: shape programs, metrics, pipeline, plots and videos.

MUJOCO_GL must be chosen before mujoco is first imported, so it is set here (EGL for off-screen
rendering without a display) unless the environment already sets it.
"""

import os as _os

_os.environ.setdefault("MUJOCO_GL", "egl")
