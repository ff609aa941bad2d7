"""Session-wide settings: headless rendering, no network, and modest threading on small CI machines."""

import os

# Before anything imports mujoco: EGL renders headless (OSMesa is not installed, GLFW needs a display).
os.environ.setdefault("MUJOCO_GL", "egl")
# Tests build their own data; any Hub access is a bug and should fail fast.
os.environ.setdefault("HF_HUB_OFFLINE", "1")


import pytest  # noqa: E402  (after the environment settings above)


@pytest.fixture
def one_torch_thread():
    """Small CPU ops on a shared 2-core machine run far faster on one thread than with two spinning OpenMP
    threads. Modules that run many small torch ops use it with `pytestmark = pytest.mark.usefixtures(...)`."""
    import torch

    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)
