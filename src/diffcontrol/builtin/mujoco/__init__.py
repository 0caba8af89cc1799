"""Gymnasium's MuJoCo environments as diffcontrol tasks, stepped by MJX on Gymnasium's own model
files (``tasks.mujoco.MujocoTask``); the ``mujoco`` extra installs what they need."""
