"""Session-wide settings: headless rendering, no network, and modest threading on small CI machines."""

import os

# Before anything imports mujoco: EGL renders headless (OSMesa is not installed, GLFW needs a display).
os.environ.setdefault("MUJOCO_GL", "egl")
# Tests build their own data; any Hub access is a bug and should fail fast.
os.environ.setdefault("HF_HUB_OFFLINE", "1")
