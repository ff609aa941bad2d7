"""rclpy.executors, as far as the glove bridge uses it."""


class ExternalShutdownException(Exception):
    """Raised by spin when the context was shut down from outside (rclpy's own signal handler)."""
