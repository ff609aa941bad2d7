"""rclpy.qos, as far as the glove bridge uses it."""

import enum


class HistoryPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


class ReliabilityPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class QoSProfile:
    def __init__(self, *, history, depth, reliability=ReliabilityPolicy.RELIABLE):
        self.history, self.depth, self.reliability = history, depth, reliability
