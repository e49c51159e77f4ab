"""DYNAMIXEL Protocol 2.0 and the X-series control table, defined once for both ends of a
servo bus: the simulator's emulated servos (`simulator.dxl_servo`, `simulator.servo_bus`) and
the companion's arm client (`companion.devices.arm`, which speaks through ROBOTIS's
dynamixel-sdk). Pure: no I/O.

Sources (ROBOTIS e-Manual, github.com/ROBOTIS-GIT/emanual):
- docs/en/dxl/protocol2.md: the packet ``FF FF FD 00 ID LEN_L LEN_H INST PARAMS CRC_L CRC_H``
  (LEN = number of parameters + 3, counted after byte stuffing), the status packet
  (INST 0x55, then the error byte: bit 7 Alert, bits 0-6 the error number 0x01 Result Fail ..
  0x07 Access), byte stuffing (``FF FF FD`` inside INST..PARAMS gets an extra ``FD``; the
  CRC covers the stuffed packet), the instructions and their examples (used as golden packets
  in tests/simulator/test_servo_bus.py).
- the e-Manual's "CRC Calculation" page (/docs/en/dxl/crc/, linked from protocol2.md): CRC-16
  with polynomial 0x8005 (x^16 + x^15 + x^2 + 1), MSB first, initial value 0, no final XOR,
  by a 256-entry table; `_CRC_TABLE` builds it from the polynomial, and the tests compare it
  entry by entry with the table in dynamixel-sdk 4.1.0 (protocol2_packet_handler.updateCRC).
- docs/en/dxl/x/xm430-w350.md and xm540-w270.md: the control table (addresses, sizes,
  access, initial values, ranges, units), stall torque, stall current and no-load speed.

Units (X series): position 1 pulse = 2 pi / 4096 rad, 2048 = joint angle 0 rad (our
convention; Homing Offset 0); velocity 1 unit = 0.229 rev/min; current 1 unit = 2.69 mA;
PWM 1 unit = 0.113 % (885 = 100 %); input voltage 0.1 V.

Servo bus of vehicle i (the simulator/companion contract, /tmp/brief.md): TCP
127.0.0.1:7200+i carries the raw bytes of the bus; servo IDs 1..n, joint j -> ID j+1.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import NamedTuple

SERVO_BUS_PORT_BASE = 7200  # TCP port of vehicle i's servo bus: 7200 + i
BROADCAST_ID = 0xFE
MAX_ID = 252
HEADER = b"\xff\xff\xfd\x00"
MAX_PACKET_LENGTH = 1024  # LEN above this is junk (dynamixel-sdk's RXPACKET_MAX_LEN)

# instructions (protocol2.md, "Instruction")
PING, READ, WRITE, REG_WRITE, ACTION, FACTORY_RESET, REBOOT, CLEAR = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x08, 0x10
STATUS = 0x55
SYNC_READ, SYNC_WRITE, BULK_READ, BULK_WRITE = 0x82, 0x83, 0x92, 0x93

# status packet error numbers (protocol2.md, "Error")
ERR_NONE, ERR_RESULT_FAIL, ERR_INSTRUCTION, ERR_CRC = 0x00, 0x01, 0x02, 0x03
ERR_DATA_RANGE, ERR_DATA_LENGTH, ERR_DATA_LIMIT, ERR_ACCESS = 0x04, 0x05, 0x06, 0x07
ERR_ALERT = 0x80
ERROR_NAMES = {ERR_RESULT_FAIL: "result fail", ERR_INSTRUCTION: "instruction error", ERR_CRC: "CRC error",
               ERR_DATA_RANGE: "data range error", ERR_DATA_LENGTH: "data length error",
               ERR_DATA_LIMIT: "data limit error", ERR_ACCESS: "access error"}

# operating modes (Operating Mode(11), control_table_opmode_six_2)
MODE_CURRENT, MODE_VELOCITY, MODE_POSITION, MODE_EXTENDED_POSITION = 0, 1, 3, 4
MODE_CURRENT_BASED_POSITION, MODE_PWM = 5, 16

# units
PULSES_PER_REV = 4096
CENTER_PULSE = 2048  # joint angle 0 rad
RAD_PER_PULSE = 2.0 * math.pi / PULSES_PER_REV
RADPS_PER_VELOCITY_UNIT = 0.229 * 2.0 * math.pi / 60.0  # 0.229 rev/min = 0.0239809 rad/s
AMPS_PER_CURRENT_UNIT = 0.00269
PWM_FULL = 885  # PWM Limit(36)'s maximum: 100 % duty
VOLTS_PER_VOLTAGE_UNIT = 0.1


def _crc_table(poly: int = 0x8005) -> tuple[int, ...]:
    table = []
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ poly) if c & 0x8000 else (c << 1)
        table.append(c & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data, crc: int = 0) -> int:
    """The Protocol 2.0 CRC of `data` (crc.md's update_crc, from `crc`)."""
    t = _CRC_TABLE
    for b in data:
        crc = ((crc << 8) ^ t[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Byte stuffing of INST..PARAMS: an ``FD`` after every ``FF FF FD``."""
    if b"\xff\xff\xfd" not in body:
        return bytes(body)
    out = bytearray()
    for k, b in enumerate(body):
        out.append(b)
        if b == 0xFD and k >= 2 and body[k - 1] == 0xFF and body[k - 2] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """The inverse of `stuff`: the ``FD`` after each ``FF FF FD`` dropped."""
    if b"\xff\xff\xfd\xfd" not in body:
        return bytes(body)
    out = bytearray()
    k, n = 0, len(body)
    while k < n:
        b = body[k]
        out.append(b)
        if b == 0xFD and k >= 2 and body[k - 1] == 0xFF and body[k - 2] == 0xFF and k + 1 < n and body[k + 1] == 0xFD:
            k += 2
        else:
            k += 1
    return bytes(out)


def packet(dxl_id: int, body: bytes) -> bytes:
    """A whole packet from its unstuffed INST..PARAMS `body`: stuffing, LEN, CRC."""
    s = stuff(body)
    head = HEADER + bytes((dxl_id & 0xFF,)) + struct.pack("<H", len(s) + 2)
    raw = head + s
    return raw + struct.pack("<H", crc16(raw))


def instruction(dxl_id: int, inst: int, params: bytes = b"") -> bytes:
    """An instruction packet."""
    return packet(dxl_id, bytes((inst,)) + bytes(params))


def status(dxl_id: int, error: int, params: bytes = b"") -> bytes:
    """A status packet (INST 0x55) with its error byte."""
    return packet(dxl_id, bytes((STATUS, error & 0xFF)) + bytes(params))


class Packet(NamedTuple):
    """One packet off the wire. `params` are unstuffed; for a status packet the first is the
    error byte. crc_ok False: the CRC did not match (params are then as received)."""

    dxl_id: int
    inst: int
    params: bytes
    crc_ok: bool


class PacketParser:
    """Packets out of a byte stream, as protocol2.md's "Processing Order of Reception": find
    ``FF FF FD 00`` (not the stuffed ``FF FF FD FD``), take LEN more bytes, check the CRC over
    the packet as received, then unstuff. Bytes between packets are skipped and counted."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.skipped_bytes = 0

    def feed(self, data: bytes) -> list[Packet]:
        buf = self._buf
        buf += data
        out: list[Packet] = []
        while True:
            start = buf.find(HEADER)
            if start < 0:
                keep = 3 if len(buf) >= 3 else len(buf)  # a header may straddle two reads
                self.skipped_bytes += len(buf) - keep
                del buf[:len(buf) - keep]
                return out
            if start:
                self.skipped_bytes += start
                del buf[:start]
            if len(buf) < 7:
                return out
            length = buf[5] | (buf[6] << 8)
            if length < 3 or length > MAX_PACKET_LENGTH:
                self.skipped_bytes += 1
                del buf[:1]
                continue
            total = 7 + length
            if len(buf) < total:
                return out
            raw = bytes(buf[:total])
            del buf[:total]
            crc_ok = crc16(raw[:-2]) == (raw[-2] | (raw[-1] << 8))
            body = raw[7:-2]
            if crc_ok:
                body = unstuff(body)
            out.append(Packet(raw[4], body[0], bytes(body[1:]), crc_ok))


# -- the X-series control table ----------------------------------------------------------
R, RW = "R", "RW"
EEPROM_END = 64  # addresses below are the EEPROM area: written only while torque is off


@dataclass(frozen=True)
class Field:
    """One control-table item: address, size [bytes], access, signedness, valid range (the
    item's own; limits set by other items, e.g. Goal Current <= Current Limit, are checked by
    the servo)."""

    name: str
    address: int
    size: int
    access: str
    signed: bool = False
    lo: int = 0
    hi: int = 0

    @property
    def eeprom(self) -> bool:
        return self.address < EEPROM_END

    def encode(self, value: int) -> bytes:
        return int(value).to_bytes(self.size, "little", signed=self.signed)

    def decode(self, data: bytes) -> int:
        return int.from_bytes(data, "little", signed=self.signed)


_U16, _U32 = 0xFFFF, 0xFFFFFFFF
# XM430-W350 / XM540-W270 control tables (e-Manual); model-specific maxima (Current Limit,
# Velocity Limit) are the servo model's (`ServoModel`)
FIELDS = (
    Field("model_number", 0, 2, R), Field("model_information", 2, 4, R), Field("firmware_version", 6, 1, R),
    Field("id", 7, 1, RW, lo=0, hi=252), Field("baud_rate", 8, 1, RW, lo=0, hi=7),
    Field("return_delay_time", 9, 1, RW, lo=0, hi=254), Field("drive_mode", 10, 1, RW, lo=0, hi=5),
    Field("operating_mode", 11, 1, RW, lo=0, hi=16), Field("secondary_id", 12, 1, RW, lo=0, hi=255),
    Field("protocol_type", 13, 1, RW, lo=1, hi=2),
    Field("homing_offset", 20, 4, RW, signed=True, lo=-1_044_479, hi=1_044_479),
    Field("moving_threshold", 24, 4, RW, lo=0, hi=1023), Field("temperature_limit", 31, 1, RW, lo=0, hi=100),
    Field("max_voltage_limit", 32, 2, RW, lo=95, hi=160), Field("min_voltage_limit", 34, 2, RW, lo=95, hi=160),
    Field("pwm_limit", 36, 2, RW, lo=0, hi=PWM_FULL), Field("current_limit", 38, 2, RW, lo=0, hi=2047),
    Field("acceleration_limit", 40, 4, RW, lo=0, hi=32767), Field("velocity_limit", 44, 4, RW, lo=0, hi=1023),
    Field("max_position_limit", 48, 4, RW, lo=0, hi=4095), Field("min_position_limit", 52, 4, RW, lo=0, hi=4095),
    Field("startup_configuration", 60, 1, RW, lo=0, hi=3), Field("shutdown", 63, 1, RW, lo=0, hi=255),
    Field("torque_enable", 64, 1, RW, lo=0, hi=1), Field("led", 65, 1, RW, lo=0, hi=1),
    Field("status_return_level", 68, 1, RW, lo=0, hi=2), Field("registered_instruction", 69, 1, R),
    Field("hardware_error_status", 70, 1, R),
    Field("velocity_i_gain", 76, 2, RW, lo=0, hi=16383), Field("velocity_p_gain", 78, 2, RW, lo=0, hi=16383),
    Field("position_d_gain", 80, 2, RW, lo=0, hi=16383), Field("position_i_gain", 82, 2, RW, lo=0, hi=16383),
    Field("position_p_gain", 84, 2, RW, lo=0, hi=16383),
    Field("feedforward_2nd_gain", 88, 2, RW, lo=0, hi=16383), Field("feedforward_1st_gain", 90, 2, RW, lo=0, hi=16383),
    Field("bus_watchdog", 98, 1, RW, lo=0, hi=127),
    Field("goal_pwm", 100, 2, RW, signed=True, lo=-PWM_FULL, hi=PWM_FULL),
    Field("goal_current", 102, 2, RW, signed=True, lo=-2047, hi=2047),
    Field("goal_velocity", 104, 4, RW, signed=True, lo=-1023, hi=1023),
    Field("profile_acceleration", 108, 4, RW, lo=0, hi=32767), Field("profile_velocity", 112, 4, RW, lo=0, hi=32767),
    Field("goal_position", 116, 4, RW, signed=True, lo=-1_048_575, hi=1_048_575),
    Field("realtime_tick", 120, 2, R), Field("moving", 122, 1, R), Field("moving_status", 123, 1, R),
    Field("present_pwm", 124, 2, R, signed=True), Field("present_current", 126, 2, R, signed=True),
    Field("present_velocity", 128, 4, R, signed=True), Field("present_position", 132, 4, R, signed=True),
    Field("velocity_trajectory", 136, 4, R, signed=True), Field("position_trajectory", 140, 4, R, signed=True),
    Field("present_input_voltage", 144, 2, R), Field("present_temperature", 146, 1, R),
)
BY_NAME = {f.name: f for f in FIELDS}
TABLE_SIZE = 147  # bytes 0..146 (the indirect addresses 168.. are not emulated)

# the items the arm client uses, as (address, size)
ADDR_OPERATING_MODE = BY_NAME["operating_mode"].address
ADDR_CURRENT_LIMIT = BY_NAME["current_limit"].address
ADDR_TORQUE_ENABLE = BY_NAME["torque_enable"].address
ADDR_GOAL_CURRENT = BY_NAME["goal_current"].address
ADDR_GOAL_POSITION = BY_NAME["goal_position"].address
ADDR_PRESENT_CURRENT = BY_NAME["present_current"].address
ADDR_PRESENT_VELOCITY = BY_NAME["present_velocity"].address
ADDR_PRESENT_POSITION = BY_NAME["present_position"].address
# Present Current, Velocity and Position are contiguous: one read of 10 bytes from 126
PRESENT_BLOCK = (ADDR_PRESENT_CURRENT, 2 + 4 + 4)


@dataclass(frozen=True)
class ServoModel:
    """A DYNAMIXEL model's numbers at 12 V (its e-Manual page's specification table).

    torque_constant_nm_per_a: stall torque / stall current. current_limit_max: Current
    Limit(38)'s range and initial value [units of 2.69 mA]. velocity_limit_init: Velocity
    Limit(44)'s initial value."""

    name: str
    model_number: int
    stall_torque_nm: float
    stall_current_a: float
    no_load_speed_rpm: float
    current_limit_max: int
    velocity_limit_init: int
    firmware_version: int = 46

    @property
    def torque_constant_nm_per_a(self) -> float:
        return self.stall_torque_nm / self.stall_current_a

    @property
    def no_load_speed_radps(self) -> float:
        return self.no_load_speed_rpm * 2.0 * math.pi / 60.0

    @property
    def nm_per_current_unit(self) -> float:
        return self.torque_constant_nm_per_a * AMPS_PER_CURRENT_UNIT


# e-Manual xm540-w270: 10.6 N m at 12.0 V, 4.4 A ("2.409 Nm/A"); 30 rev/min no load; Current
# Limit 0..2047 (initial 2047); Velocity Limit initial 128. The project's joint-effort model
# (simulator/devices.py's JointEffortSensor, configs/randomize/default.toml
# [randomize.devices.effort]) uses the same torque constant: one current unit is 6.48 mN m.
XM540_W270 = ServoModel("XM540-W270", 1120, 10.6, 4.4, 30.0, 2047, 128)
# e-Manual xm430-w350: 4.1 N m at 12.0 V, 2.3 A (1.78 N m/A, our quotient); 46 rev/min;
# Current Limit 0..1193 (initial 1193); Velocity Limit initial 350.
XM430_W350 = ServoModel("XM430-W350", 1020, 4.1, 2.3, 46.0, 1193, 350)
MODELS = {m.model_number: m for m in (XM540_W270, XM430_W350)}


def joint_id(j: int) -> int:
    """The servo ID of joint j (0-based): j + 1."""
    return j + 1


def servo_bus_port(index: int) -> int:
    """The TCP port of vehicle `index`'s servo bus (0-based [[am]] order)."""
    return SERVO_BUS_PORT_BASE + index


def rad_to_pulse(q_rad: float) -> int:
    """Present/Goal Position [pulse] of joint angle q [rad] (2048 = 0 rad), rounded."""
    return CENTER_PULSE + int(round(q_rad / RAD_PER_PULSE))


def pulse_to_rad(pulse: int) -> float:
    return (pulse - CENTER_PULSE) * RAD_PER_PULSE


def radps_to_velocity(qdot_radps: float) -> int:
    return int(round(qdot_radps / RADPS_PER_VELOCITY_UNIT))


def velocity_to_radps(units: int) -> float:
    return units * RADPS_PER_VELOCITY_UNIT


def error_text(error: int) -> str:
    """A status packet's error byte in words."""
    num = error & 0x7F
    words = ERROR_NAMES.get(num, f"error {num:#04x}") if num else "no error"
    return words + (" (alert: hardware error status set)" if error & ERR_ALERT else "")
