"""Evaluation of domain translation: the five shapes scored in the simulator, plots and videos.

`mjx_arm` is imported first, so that its choices are made before anything here imports mujoco
or jax: the XLA CPU flag and MUJOCO_GL (EGL for off-screen rendering when there is no display
and libEGL can be found; otherwise left as the environment has it).
"""

import mjx_arm  # noqa: F401
