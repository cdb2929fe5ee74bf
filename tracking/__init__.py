"""Tracking: the non-learned ways to make the constrained arm (D_c) follow the source arm (D_s).

The layer between the simulator (`mjx_arm`) and the learned translators (`ccgan`), so that both
the fine-tunes and the evaluation (`eval`) draw on one copy of each piece:

  config   ConfigError and field checks shared by every settings dataclass above it
  metrics  X_err (cm), phi_err (rad), summaries, and the differentiable tracking loss
  held     held commands: stretch k, every k-th pose, D_c rollouts of held programs
  mpc      receding-horizon tracking in the D_c simulator (MuJoCo C, Gauss-Newton)
  oracle   D_c commands optimised through the differentiable MJX rollout (Adam)

Nothing here imports `ccgan`, `eval` or `bench` (tests/test_layers.py checks it).
"""
