"""A stand-in for rclpy (ROS 2 Humble's Python API), for the glove bridge's tests: the calls the bridge makes, and a
`spin` that plays recorded `ManusGlove` messages to the subscriptions as MANUS's `manus_data_publisher` publishes
them, one round of messages every 10 ms, the last round repeated until the process is interrupted.

$FAKE_ROS2_ROUNDS: a JSON file, a list of rounds, each a list of {"topic", "glove_id", "side", "ergonomics":
[[type, value], ...]}. $FAKE_ROS2_LOG: each call of the bridge is appended to this file.
"""

import json
import os
import time

from .qos import HistoryPolicy, QoSProfile

_context = {"ok": False}


def _log(line: str) -> None:
    with open(os.environ["FAKE_ROS2_LOG"], "a") as f:
        f.write(line + "\n")


def init(args=None):
    if _context["ok"]:
        raise RuntimeError("rclpy.init() called twice")
    _context["ok"] = True
    _log("init")


def ok():
    return _context["ok"]


def shutdown():
    if not _context["ok"]:
        raise RuntimeError("rclpy.shutdown() without init, or twice")
    _context["ok"] = False
    _log("shutdown")


class Node:
    def __init__(self, name):
        self.name, self.subscriptions, self.timers = name, {}, []

    def create_subscription(self, msg_type, topic, callback, qos_profile):
        if not isinstance(qos_profile, QoSProfile) or qos_profile.history != HistoryPolicy.KEEP_LAST:
            raise TypeError(f"qos_profile must be a KEEP_LAST QoSProfile, not {qos_profile!r}")
        _log(f"subscribe {topic} {msg_type.__module__}.{msg_type.__name__} depth={qos_profile.depth}")
        self.subscriptions[topic] = (msg_type, callback)

    def create_timer(self, period_s, callback):
        self.timers.append([period_s, time.monotonic() + period_s, callback])

    def destroy_node(self):
        _log("destroy_node")


def create_node(name):
    _log(f"create_node {name}")
    return Node(name)


def _message(msg_type, spec):
    ergonomics_type = __import__(msg_type.__module__, fromlist=["ManusErgonomics"]).ManusErgonomics
    ergonomics = [ergonomics_type(type=t, value=v) for t, v in spec["ergonomics"]]
    return msg_type(
        glove_id=spec["glove_id"],
        side=spec["side"],
        raw_node_count=0,
        raw_nodes=[],
        ergonomics_count=len(ergonomics),
        ergonomics=ergonomics,
        raw_sensor_count=0,
        raw_sensor=[],
    )


def spin(node):
    with open(os.environ["FAKE_ROS2_ROUNDS"]) as f:
        rounds = json.load(f)
    k = 0
    while _context["ok"]:
        for spec in rounds[min(k, len(rounds) - 1)]:
            if spec["topic"] in node.subscriptions:
                msg_type, callback = node.subscriptions[spec["topic"]]
                callback(_message(msg_type, spec))
        for timer in node.timers:
            if time.monotonic() >= timer[1]:
                timer[1] += timer[0]
                timer[2]()
        k += 1
        time.sleep(0.01)
