"""The emulators speak the real protocols: the unmodified dynamixel-sdk talks to the servo emulator, and the force
frame codec survives what a USB serial line does to it. (What the emulators are worth is what the other hardware
tests are worth.)"""

from __future__ import annotations

import random
import time

import numpy as np
import pytest
from dynamixel_sdk import COMM_RX_CORRUPT, COMM_RX_TIMEOUT, COMM_SUCCESS, PacketHandler, PortHandler
from dynamixel_sdk import protocol2_packet_handler as p2
from emulators.faults import FaultyBus
from emulators.rig import LATENCY_TIMER_MS

from lerobot_blindgrasp import spec
from lerobot_blindgrasp.emulators.control_table import CONTROL_TABLE, HW_OVERLOAD, XM430_W350_MODEL
from lerobot_blindgrasp.emulators.dynamixel import DynamixelBusEmulator, EmulatedServo
from lerobot_blindgrasp.emulators.dynamixel_wire import crc16, stuff, unstuff
from lerobot_blindgrasp.hardware.force_board.frame_codec import FrameParser, crc16_ccitt_false, encode_frame
from lerobot_blindgrasp.robots.blindgrasp_gripper import BlindgraspGripper, BlindgraspGripperConfig

ADDR = {name: spec_[0] for name, spec_ in CONTROL_TABLE.items()}


@pytest.fixture
def bus():
    with FaultyBus([10, 11, 12]) as emu:
        port = PortHandler(emu.port)
        assert port.openPort() and port.getBaudRate() == 1_000_000
        yield emu, port, PacketHandler(2.0)
        port.closePort()


def test_crc_and_byte_stuffing_match_the_sdk():
    ph = PacketHandler(2.0)
    rng = random.Random(0)
    for _ in range(200):
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64)))
        assert crc16(data) == ph.updateCRC(0, list(data), len(data))
    raw = bytes([0x55, 0x00, 0xFF, 0xFF, 0xFD, 0x01])
    assert stuff(raw) == bytes([0x55, 0x00, 0xFF, 0xFF, 0xFD, 0xFD, 0x01]) and unstuff(stuff(raw)) == raw


def test_ping_read_write_and_broadcast_ping(bus):
    emu, port, ph = bus
    model, comm, err = ph.ping(port, 11)
    assert (model, comm, err) == (XM430_W350_MODEL, COMM_SUCCESS, 0)
    found, comm = ph.broadcastPing(port)
    assert comm == COMM_SUCCESS and sorted(found) == [10, 11, 12]
    assert ph.write2ByteTxRx(port, 12, ADDR["Position_P_Gain"], 1234) == (COMM_SUCCESS, 0)
    assert ph.read2ByteTxRx(port, 12, ADDR["Position_P_Gain"]) == (1234, COMM_SUCCESS, 0)
    # A value whose bytes contain FF FF FD travels stuffed, both ways, and arrives intact.
    value = 0x00FDFFFF
    assert ph.write4ByteTxRx(port, 10, ADDR["Profile_Velocity"], value) == (COMM_SUCCESS, 0)
    assert emu.servos[10].get("Profile_Velocity") == value
    assert ph.read4ByteTxRx(port, 10, ADDR["Profile_Velocity"]) == (value, COMM_SUCCESS, 0)


def test_control_table_rules(bus):
    emu, port, ph = bus
    assert ph.write2ByteTxRx(port, 10, ADDR["Present_Position"], 5) == (
        COMM_SUCCESS,
        p2.ERRNUM_ACCESS,
    )  # read-only
    assert ph.write1ByteTxRx(port, 10, ADDR["Operating_Mode"], 2) == (COMM_SUCCESS, p2.ERRNUM_DATA_RANGE)
    assert ph.write1ByteTxRx(port, 10, ADDR["Torque_Enable"], 1) == (COMM_SUCCESS, 0)
    # EEPROM is locked while the torque is on.
    assert ph.write1ByteTxRx(port, 10, ADDR["Operating_Mode"], 5) == (COMM_SUCCESS, p2.ERRNUM_ACCESS)
    assert emu.servos[10].get("Operating_Mode") == 3
    assert ph.write2ByteTxRx(port, 10, ADDR["Goal_Current"], 2000) == (COMM_SUCCESS, p2.ERRNUM_DATA_LIMIT)


def test_sync_read_and_sync_write_move_the_shafts(bus):
    from dynamixel_sdk import GroupSyncRead, GroupSyncWrite

    emu, port, ph = bus
    writer = GroupSyncWrite(port, ph, ADDR["Goal_Position"], 4)
    for i in (10, 11, 12):
        assert ph.write1ByteTxRx(port, i, ADDR["Torque_Enable"], 1)[0] == COMM_SUCCESS
        writer.addParam(i, list((2048 + i * 10).to_bytes(4, "little")))
    assert writer.txPacket() == COMM_SUCCESS
    time.sleep(0.3)
    reader = GroupSyncRead(port, ph, ADDR["Present_Position"], 4)
    for i in (10, 11, 12):
        reader.addParam(i)
    assert reader.txRxPacket() == COMM_SUCCESS
    assert [reader.getData(i, ADDR["Present_Position"], 4) for i in (10, 11, 12)] == [2148, 2158, 2168]


def test_faults_look_like_real_ones(bus):
    emu, port, ph = bus
    emu.missing_ids.add(11)
    assert ph.ping(port, 11)[1] == COMM_RX_TIMEOUT
    emu.missing_ids.clear()
    emu.drop_responses[12] = 1
    assert ph.ping(port, 12)[1] == COMM_RX_TIMEOUT
    assert ph.ping(port, 12)[1] == COMM_SUCCESS  # one dropped reply only
    emu.corrupt_responses[10] = 1
    assert ph.ping(port, 10)[1] == COMM_RX_CORRUPT
    # Hardware error: torque drops, every status packet carries the alert bit, torque stays off until a reboot.
    assert ph.write1ByteTxRx(port, 11, ADDR["Torque_Enable"], 1) == (COMM_SUCCESS, 0)
    emu.set_hardware_error(11, HW_OVERLOAD)
    assert ph.read1ByteTxRx(port, 11, ADDR["Hardware_Error_Status"]) == (
        HW_OVERLOAD,
        COMM_SUCCESS,
        p2.ERRBIT_ALERT,
    )
    assert not emu.torque_enabled(11)
    ph.write1ByteTxRx(port, 11, ADDR["Torque_Enable"], 1)
    assert not emu.torque_enabled(11)
    assert ph.reboot(port, 11)[0] == COMM_SUCCESS
    assert ph.read1ByteTxRx(port, 11, ADDR["Hardware_Error_Status"]) == (0, COMM_SUCCESS, 0)


def test_servos_only_answer_at_their_baud_rate(bus):
    emu, port, ph = bus
    assert port.setBaudRate(57_600)
    assert ph.ping(port, 10)[1] == COMM_RX_TIMEOUT
    assert port.setBaudRate(1_000_000)
    assert ph.ping(port, 10)[1] == COMM_SUCCESS


def test_setup_motors_gives_factory_servos_their_ids_and_baud(tmp_path, monkeypatch):
    """lerobot-setup-motors: one factory-fresh servo (ID 1, 57 600 bps) on the cable at a time."""
    with DynamixelBusEmulator([1], baudrate=57_600) as emu:
        configured = []

        def plug_next_servo(prompt: str = "") -> str:
            fresh = EmulatedServo(1)
            fresh.set("Baud_Rate", 1)  # 57 600 bps
            emu.servos = {1: fresh}
            configured.append(fresh)
            return ""

        monkeypatch.setattr("builtins.input", plug_next_servo)
        robot = BlindgraspGripper(
            BlindgraspGripperConfig(
                id="new", port=emu.port, calibration_dir=tmp_path, latency_timer_ms=LATENCY_TIMER_MS
            )
        )
        robot.setup_motors()
    assert [s.get("ID") for s in configured] == list(reversed(spec.SERVO_IDS))
    assert {s.get("Baud_Rate") for s in configured} == {3}  # 1 Mbps


def test_force_frames_resync_after_garbage_and_bad_crcs():
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    rng = np.random.default_rng(0)
    frames = [encode_frame(k, rng.integers(-(2**23), 2**23, 3).tolist(), k % 2) for k in range(50)]
    bad = bytearray(frames[10])
    bad[7] ^= 0x01  # one flipped bit in a count
    stream = b"".join(frames[:10]) + bytes(bad) + b"\xa5\x5a\x99junk\xa5" + b"".join(frames[11:])
    parser = FrameParser()
    out = []
    for k in range(0, len(stream), 7):  # arrives in arbitrary chunks
        out += parser.feed(stream[k : k + 7])
    assert [f.seq for f in out] == [k for k in range(50) if k != 10]
    assert out[0].counts == tuple(int(c) for c in np.frombuffer(frames[0][5:17], "<i4"))
    assert parser.crc_errors == 1 and parser.bad_lengths >= 1


def test_the_parser_never_asks_for_bytes_past_the_frame_in_progress():
    """`wanted()` is what the reader's serial read may wait for: reading exactly that many bytes at a time, each
    read ends with a whole frame (so it is stamped on arrival), garbage and a bad CRC included."""
    frames = [encode_frame(k, [k, -k, 2 * k]) for k in range(5)]
    stream = b"\x00\xa5" + frames[0] + frames[1][:-1] + b"\x00" + b"".join(frames[2:])
    parser, pos, done = FrameParser(), 0, []
    while pos < len(stream):
        n = parser.wanted()
        got = parser.feed(stream[pos : pos + n])
        pos += n
        done.append((pos, [f.seq for f in got]))
    ends = {len(b"\x00\xa5" + frames[0]): [0]}
    for k in range(2, 5):
        ends[len(stream) - len(b"".join(frames[k + 1 :]))] = [k]
    assert {p: seqs for p, seqs in done if seqs} == ends
    assert parser.crc_errors == 1
