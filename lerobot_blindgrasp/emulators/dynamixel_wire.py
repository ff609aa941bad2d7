"""Dynamixel Protocol 2.0 on the wire (ROBOTIS e-Manual, "DYNAMIXEL Protocol 2.0"): the packet
`FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAMS | CRC_L CRC_H`, its CRC-16 (poly 0x8005) and byte stuffing."""

from __future__ import annotations

HEADER = b"\xff\xff\xfd\x00"


def crc16(data: bytes | bytearray) -> int:
    """Protocol 2.0 CRC-16 (polynomial 0x8005, no reflection, init 0), bitwise."""
    crc = 0
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Insert 0xFD after every FF FF FD inside INST..PARAMS (the header itself is not stuffed)."""
    out = bytearray()
    for b in body:
        out.append(b)
        if len(out) >= 3 and out[-3:] == b"\xff\xff\xfd":
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        if len(out) >= 3 and out[-3:] == b"\xff\xff\xfd" and i + 1 < len(body) and body[i + 1] == 0xFD:
            i += 1  # drop the stuffing byte
        i += 1
    return bytes(out)


def make_packet(dxl_id: int, instruction: int, params: bytes = b"", *, bad_crc: bool = False) -> bytes:
    body = stuff(bytes([instruction]) + bytes(params))
    length = len(body) + 2
    pkt = HEADER + bytes([dxl_id, length & 0xFF, length >> 8]) + body
    crc = crc16(pkt) ^ (0x5A5A if bad_crc else 0)
    return pkt + bytes([crc & 0xFF, crc >> 8])


def crc_ok(pkt: bytes) -> bool:
    return crc16(pkt[:-2]) == (pkt[-2] | (pkt[-1] << 8))
