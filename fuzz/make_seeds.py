#!/usr/bin/env python3
"""Writes the fuzz seed corpus: every example frame quoted in the manuals (PROTOCOLS.md)."""
import pathlib

ROOT = pathlib.Path(__file__).parent / "seeds"

def can(id_, hex_):
    return id_.to_bytes(2, "little") + bytes.fromhex(hex_)

SEEDS = {
    "titan_decode": {
        "motion-150mm": can(0x111, "0096000000000000"),
        "mode-can": can(0x421, "01"),
        "brake-release": can(0x131, "01"),
        "status-heartbeat-lost": can(0x211, "000101E000000200"),
        "steering-zero-ack": can(0x43A, "EE"),
        "bms-alarm": can(0x362, "84010200"),
    },
    "scout_mini_decode": {
        "forward-0.5": can(0x130, "01000A0000000044"),
        "rotate-10pct": can(0x130, "0100000A00000044"),
        "command-mode": can(0x130, "010000000000003A"),
        "bad-checksum": can(0x130, "01000A0000000045"),
    },
    "xbot_stream": {
        "power-on": b"\x01" + bytes.fromhex("AA5502010102"),
        "forward-0.2": b"\x05" + bytes.fromhex("AA550D03CDCC4C3E00000000000000007D"),
        "lift-10": b"\x02" + bytes.fromhex("AA550304010A0C"),
        "servos": b"\x03" + bytes.fromhex("AA55030500 5A5C".replace(" ", "")),
        "sensor": b"\x10" + bytes.fromhex(
            "AA5547100162260302000100000005 0A00060000000000060003000000000000050000000000000000"
            "E80301000000000000000000000000000000000000000000000000000000000002DC2F".replace(" ", "")),
        "garbage-then-frame": b"\x04" + bytes.fromhex("00AA12AA55AA5502010102"),
    },
    "nmea_stream": {
        "gga": b"$GPGGA,092750.000,5321.6802,N,00630.3372,W,1,8,1.03,61.7,M,55.2,M,,*76\r\n",
        "rmc-no-fix": b"$GPRMC,235947.000,V,0000.0000,N,00000.0000,E,,,041299,,*1D\r\n",
    },
    "candump_text": {
        "frame": b"111#0096000000000000",
        "log-line": b"(1700000000.000000) can0 123#DEADBEEF",
    },
}

for target, seeds in SEEDS.items():
    d = ROOT / target
    d.mkdir(parents=True, exist_ok=True)
    for name, data in seeds.items():
        (d / name).write_bytes(data)
print("seeds written to", ROOT)
