"""Glove time by the bridge's clock: order by the bridge's sequence, age by its clock, tell a restarted bridge from
late datagrams. First the receiver's rules on a simulated clock (fuzzed with hypothesis), then the teleoperator
against the emulated bridge over UDP, with the network's faults."""

from __future__ import annotations

import itertools
import json
import logging
import re
import sys
import threading
import time

import numpy as np
import pytest
from emulators.glove_sender import FIST, OPEN, GloveEmulator, free_udp_port
from hypothesis import given, settings
from hypothesis import strategies as st

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.teleoperators.manus_glove import ManusGlove, ManusGloveConfig, receiver
from lerobot_blindgrasp.teleoperators.manus_glove.manus_glove import GloveStreamLost
from lerobot_blindgrasp.teleoperators.manus_glove.protocol import GloveDatagram, GloveSender
from lerobot_blindgrasp.teleoperators.manus_glove.receiver import OFFSET_LEAK, GloveReceiver
from lerobot_blindgrasp.teleoperators.manus_glove.retarget import REQUIRED_KEYS

ERGO = dict.fromkeys(REQUIRED_KEYS, 1.0)


def _receiver(max_latency_s: float = 0.1) -> GloveReceiver:
    return GloveReceiver("127.0.0.1", 0, "right", REQUIRED_KEYS, max_latency_s=max_latency_s)  # never opened


def _datagram(seq: int, sent: float, session: str = "a") -> GloveDatagram:
    return GloveDatagram(session, seq, sent, "right", ERGO)


# --- the rules, on a simulated clock -------------------------------------------------------------------------------
def test_a_late_or_duplicated_datagram_is_dropped_however_late():
    r = _receiver()
    clock_offset = 5000.0  # the bridge's clock and ours need not agree
    kept = []
    for seq in range(1, 101):
        if (f := r._order_and_age(_datagram(seq, seq * 0.01), seq * 0.01 + clock_offset + 0.001)) is not None:
            kept.append(f.seq)
    # seq 20 again 80 frames later (duplicated), and seq 60 arriving after seq 100 (delayed far past any window)
    assert r._order_and_age(_datagram(20, 0.2), 1.001 + clock_offset) is None
    assert r._order_and_age(_datagram(60, 0.6), 1.002 + clock_offset) is None
    assert kept == list(range(1, 101)) and r.late == 2


def test_a_backlog_after_a_network_pause_is_not_replayed():
    r = _receiver(max_latency_s=0.1)
    for seq in range(1, 11):  # live: 10 ms apart, 1 ms on the way
        assert r._order_and_age(_datagram(seq, seq * 0.01), seq * 0.01 + 0.001) is not None
    # A 2 s pause: the frames sent meanwhile all arrive at t = 2.1 s, then live frames follow.
    backlog = [r._order_and_age(_datagram(seq, seq * 0.01), 2.1) for seq in range(11, 211)]
    kept = [f.seq for f in backlog if f is not None]
    assert all(2.1 - (s * 0.01 + 0.001) <= 0.1 + OFFSET_LEAK * 2.1 for s in kept)  # only what is <= 100 ms late
    assert r.stale == 200 - len(kept) and r.stale >= 185
    live = r._order_and_age(_datagram(211, 2.11), 2.111)
    assert live is not None and live.sent_local == pytest.approx(2.11 + 0.001, abs=OFFSET_LEAK * 2.2)


def test_a_restarted_bridge_is_followed_and_its_old_session_dropped(caplog):
    r = _receiver()
    for seq in range(1, 6):
        assert r._order_and_age(_datagram(seq, seq * 0.01, "old"), seq * 0.01 + 0.001) is not None
    with caplog.at_level(logging.WARNING):
        f = r._order_and_age(_datagram(1, 900.0, "new"), 0.1)  # a new process: counter from 1, another clock
    assert f is not None and f.session == "new" and r.restarts == 1
    assert "Glove bridge restarted (session old -> new" in caplog.text
    assert r._order_and_age(_datagram(6, 0.06, "old"), 0.11) is None and r.retired == 1  # late, of the old one
    assert r._order_and_age(_datagram(2, 900.01, "new"), 0.111) is not None


events = st.lists(
    st.tuples(
        st.booleans(),  # the bridge restarts before this datagram (new session, counter from 1)
        st.floats(0.0, 0.3),  # this datagram's delay on the way (s)
        st.booleans(),  # it is delivered twice
    ),
    min_size=1,
    max_size=60,
)


def _network(events, pause_start: float, pause_s: float, period: float = 0.01):
    """(arrival, session, seq, sent) in arrival order. Sessions share one clock, as restarts on one machine do.
    What would arrive during the pause arrives at its end, in one burst."""
    out, session, seq = [], 0, 0
    for i, (restart, delay, twice) in enumerate(events):
        if restart and i:
            session, seq = session + 1, 0
        seq += 1
        at = i * period + delay
        if pause_start <= at < pause_start + pause_s:
            at = pause_start + pause_s
        out += [(at, session, seq, i * period)] * (2 if twice else 1)
    return sorted(out, key=lambda a: a[0])


@settings(max_examples=300, deadline=None)
@given(events=events, pause_start=st.floats(0.0, 0.6), pause_s=st.floats(0.0, 3.0))
def test_fuzz_orderings_never_step_back_nor_use_a_stale_pose(events, pause_start, pause_s):
    """Any delays, duplicates, restarts and a network pause: the poses used are in the bridge's order, by its
    clock and within each session by its counter; and none was queued on the way longer than the limit (judged
    against the fastest delivery seen in its session, allowing for the estimate's upward leak)."""
    max_latency = 0.1
    r = _receiver(max_latency)
    kept, fastest, first_at = [], {}, {}
    for at, session, seq, sent in _network(events, pause_start, pause_s):
        f = r._order_and_age(_datagram(seq, sent, f"s{session}"), at)
        delay = at - sent
        if r.session == f"s{session}":
            fastest[session] = min(fastest.get(session, delay), delay)
            first_at.setdefault(session, at)
        if f is not None:
            kept.append((sent, session, seq))
            assert delay - fastest[session] <= max_latency + OFFSET_LEAK * (at - first_at[session]) + 1e-9
            assert f.sent_local <= at + 1e-9  # a pose is never younger than its arrival
    assert [k[0] for k in kept] == sorted(
        {k[0] for k in kept}
    )  # strictly later each time: no step back, no repeat
    assert [k[1] for k in kept] == sorted(k[1] for k in kept)  # a restarted bridge is never left for an older one
    if events and pause_s == 0 and all(d < max_latency for _, d, _ in events):
        assert kept  # a calm network delivers


class PreemptedClocks:
    """The host's clocks as the receiver reads them, with its thread preempted for `lag_s` between a monotonic and
    a wall-clock read once armed: from then on both clocks read `lag_s` later, as after any preemption."""

    def __init__(self, lag_s: float):
        self.lag_s, self.armed, self.shift = lag_s, False, 0.0

    def monotonic(self) -> float:
        return time.monotonic() + self.shift

    def time(self) -> float:
        if self.armed:
            self.armed, self.shift = False, self.lag_s
        return time.time() + self.shift


@pytest.mark.skipif(sys.platform != "linux", reason="kernel arrival stamps (SO_TIMESTAMPNS) are Linux's")
@pytest.mark.parametrize("preempted", [False, True], ids=["", "preempted between the clock reads"])
def test_a_busy_host_is_not_taken_for_a_network_pause(monkeypatch, preempted):
    """Datagrams that waited in the socket buffer while this process was busy were not queued on the network: they
    are kept (by the kernel's arrival stamps), and their age still counts the wait. A preemption between the
    receiver's two clock reads, twice the wall-clock step it watches for, is not taken for a step of the clock."""
    clocks = PreemptedClocks(2 * receiver.WALL_STEP_S)
    monkeypatch.setattr(receiver, "time", clocks)
    port = free_udp_port()
    # The wait below is three times max_latency_s; max_latency_s itself is the margin a busy test process has
    # between a datagram's `sent` stamp and its send call, which would count as time on the network.
    r = GloveReceiver("127.0.0.1", port, "right", REQUIRED_KEYS, max_latency_s=0.25)
    r._open()  # no receive thread: this process "does not get to read" for a while
    sender = GloveSender("127.0.0.1", port, "right")
    try:
        for _ in range(3):  # read as they come: the clock offset is known
            sender.send(ERGO)
            assert len(r._receive()) == 1
        for _ in range(5):
            sender.send(ERGO)
            time.sleep(0.01)
        time.sleep(0.75)
        clocks.armed = preempted
        frames = [f for _ in range(5) for f in r._receive()]
        assert [f.seq for f in frames] == [4, 5, 6, 7, 8] and r.stale == 0
        assert not clocks.armed and clocks.monotonic() - frames[-1].sent_local >= 0.75  # it waited here too
    finally:
        r._close()
        sender.close()


# --- the teleoperator against the emulated bridge ------------------------------------------------------------------
@pytest.fixture
def rig(tmp_path):
    (tmp_path / "op.json").write_text(json.dumps({"open": OPEN, "fist": FIST}))
    port = free_udp_port()
    with GloveEmulator(port, rate_hz=100.0) as glove:
        teleop = ManusGlove(ManusGloveConfig(id="op", port=port, calibration_dir=tmp_path))
        teleop.connect()
        try:
            yield teleop, glove
        finally:
            teleop.disconnect()


def _closure(teleop) -> float:
    """The operator's closure the action shows, from the proximal flexion joints (0 open .. 1 fist)."""
    a = teleop.get_action()
    q = np.array([a[k] for k in spec.ACTION_NAMES])
    lo, hi = np.array(teleop.config.open_pose), np.array(teleop.config.closed_pose)
    return float(np.mean((q[[1, 4, 7]] - lo[[1, 4, 7]]) / (hi[[1, 4, 7]] - lo[[1, 4, 7]])))


def _watch(teleop, seconds: float) -> list[float]:
    out, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        out.append(_closure(teleop))
        time.sleep(0.005)
    return out


def test_delayed_and_duplicated_datagrams_never_step_the_action_back(rig):
    teleop, glove = rig
    t0 = time.monotonic()
    glove.closure_fn = lambda t: min(1.0, max(0.0, (time.monotonic() - t0) / 1.5))  # closing steadily over 1.5 s

    def faults():
        for k in range(12):
            time.sleep(0.1)
            (glove.delay_next if k % 2 else glove.duplicate_next)(40)  # 40 frames: past the old 16-frame window

    th = threading.Thread(target=faults)
    th.start()
    seen = _watch(teleop, 1.6)
    th.join()
    assert teleop.receiver.late >= 6  # the faults did reach the receiver
    assert all(b >= a - 1e-9 for a, b in itertools.pairwise(seen)), "the action stepped back to an older hand pose"
    assert seen[-1] > 0.8


def test_after_a_network_pause_the_action_holds_then_follows_live_data(rig, caplog):
    teleop, glove = rig
    glove.closure = 0.0
    assert teleop.receiver.wait_frames(5, 2.0) and _closure(teleop) == pytest.approx(0.0, abs=1e-9)
    glove.stalled = True  # the network holds everything from here
    glove.closure = 0.5  # what the hand did during the pause: must never be replayed
    time.sleep(0.4)
    glove.closure = 1.0  # the hand now, a little before the network comes back
    during = _watch(teleop, 0.2)
    with caplog.at_level(logging.WARNING):
        glove.stalled = False  # the backlog arrives in one burst, then the live stream
        after = _watch(teleop, 0.3)
    assert all(c == pytest.approx(0.0, abs=1e-9) for c in during)  # held at the last live pose
    assert all(c == pytest.approx(0.0, abs=1e-9) or c == pytest.approx(1.0, abs=1e-9) for c in after), (
        "a pose from the pause was replayed"
    )
    assert after[-1] == pytest.approx(1.0, abs=1e-9)
    assert teleop.receiver.stale >= 10 and "whose backlog is not replayed" in caplog.text


def test_a_restarted_bridge_is_followed_after_a_warning(rig, caplog):
    teleop, glove = rig
    glove.closure = 0.0
    assert teleop.receiver.wait_frames(3, 2.0)
    with caplog.at_level(logging.WARNING):
        glove.closure = 1.0
        glove.restart()
        assert teleop.receiver.wait_frames(3, 2.0)
        assert _closure(teleop) == pytest.approx(1.0, abs=1e-9)
    assert teleop.receiver.restarts == 1 and "Glove bridge restarted" in caplog.text


def test_a_bridge_clock_that_jumps_ahead_is_followed(rig, caplog):
    """The bridge's `sent` jumps 5 s ahead within its session: no longer this machine's clock, so the receiver says
    so and ages by an estimated offset; the poses stay live."""
    teleop, glove = rig
    with caplog.at_level(logging.WARNING):
        glove.clock_offset_s = 5.0
        glove.closure = 1.0
        time.sleep(0.3)
        action = teleop.get_action()
    assert "not this machine's monotonic clock" in caplog.text
    assert action["ff_j11.pos"] == pytest.approx(teleop.config.closed_pose[1], abs=1e-6)  # the fist, live
    assert teleop.receiver.stale == 0 and teleop.receiver.latest()[1] < 0.05


def test_a_bridge_clock_that_steps_back_is_named_and_stops(rig, caplog):
    """The bridge's `sent` steps 5 s back while its `seq` goes on: not a late datagram, a clock that is not
    monotonic. Its poses cannot be aged: dropped, the action holds, then the stream is lost, and both say why."""
    teleop, glove = rig
    held = teleop.get_action()
    with caplog.at_level(logging.WARNING):
        glove.clock_offset_s = -5.0
        glove.closure = 1.0
        time.sleep(0.3)
        assert teleop.get_action() == held  # holding the last live target
        time.sleep(0.8)
        with pytest.raises(GloveStreamLost, match=r"after the bridge's clock stepped back"):
            teleop.get_action()
    assert re.search(r"clock stepped back 4\.9\d\d s", caplog.text) and teleop.receiver.late == 0  # 5 s - a frame
