#!/usr/bin/env python3
"""Writes seed inputs for the decode_bytes target into seeds/decode_bytes/:
byte 0 = configuration flags, byte 1 = chunk seed, then a stream of valid
MAVLink 2 frames (autopilot heartbeat and pose, a GCS setpoint)."""
import os, struct

EXTRA = {0: 50, 30: 39, 32: 185, 82: 49, 84: 143, 102: 158, 253: 83, 331: 91}

def x25(data, crc=0xFFFF):
    for b in data:
        t = b ^ (crc & 0xFF)
        t = (t ^ (t << 4)) & 0xFF
        crc = ((crc >> 8) ^ (t << 8) ^ (t << 3) ^ (t >> 4)) & 0xFFFF
    return crc

def frame(msg_id, payload, sys=1, comp=1, seq=20):
    while payload and payload[-1] == 0:
        payload = payload[:-1]
    hdr = bytes([0xFD, len(payload), 0, 0, seq, sys, comp]) + msg_id.to_bytes(3, "little")
    crc = x25(hdr[1:] + payload)
    crc = x25(bytes([EXTRA[msg_id]]), crc)
    return hdr + payload + struct.pack("<H", crc)

hb = frame(0, struct.pack("<IBBBBB", 0, 2, 12, 0x81, 4, 3))
lpn = lambda t, x: frame(32, struct.pack("<I6f", t, x, 0.0, -10.0, 0, 0, 0))
att = frame(30, struct.pack("<I6f", 100, 0.01, 0.02, 0.3, 0, 0, 0))
sp = frame(84, struct.pack("<I11fHBBB", 100, 5.0, 1.0, -10.0, 0, 0, 0, 0, 0, 0, 0.5, 0, 0xFF8, 1, 191, 1), sys=255, comp=190)
odom = frame(331, struct.pack("<Q3f3f4f3f21f21fBBBBb", 1_000_000, 1, 2, -3, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, *([0.0] * 42), 1, 12, 0, 1, 80))
vpe = frame(102, struct.pack("<Q6f", 1_000_000, 1, 2, -3, 0, 0, 0.5))
seeds = {
    "lpn_hold_setpoint": bytes([0, 7]) + hb + b"".join(lpn(100 + 20 * i, 1.0) for i in range(10)) + sp + hb + att,
    "odom": bytes([1, 3]) + hb + odom + odom + sp,
    "vpe": bytes([2, 5]) + hb + vpe + vpe + sp,
}
os.makedirs("seeds/decode_bytes", exist_ok=True)
for name, data in seeds.items():
    open(os.path.join("seeds/decode_bytes", name), "wb").write(data)
