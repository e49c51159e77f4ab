"""ATI Net F/T's Raw Data Transfer (RDT) over UDP, defined once for both ends: the simulator's
emulated wrist sensor (`simulator.netft`) and the companion's client
(`companion.devices.netft`). Pure: no I/O.

Source: ATI Industrial Automation, "Net F/T Installation and Operation Manual", document
9620-05-Net FT, section "UDP Interface Using RDT" (the same protocol as the Ethernet Axia
manuals 9610-05 / 9620-05-C, "RDT Protocol"); the command codes agree with ATI's C demo and
the ROS netft_rdt_driver. All multi-byte values big-endian ("high byte first").

- Port: the sensor listens on UDP 49152 and answers the address and port that sent the
  command; a command from another client takes precedence (it becomes the one streamed to).
- Request, 8 bytes: uint16 command_header = 0x1234, uint16 command, uint32 sample_count
  (records to send, 0 = until a stop command).
- Commands: 0x0000 stop streaming; 0x0002 start high-speed real-time streaming (one record
  per datagram); 0x0003 start high-speed buffered streaming (several records per datagram,
  the sensor's "RDT buffer size"); 0x0004 start multi-unit streaming (not emulated);
  0x0041 reset threshold latch; 0x0042 set software bias (the present reading becomes zero).
- Record, 36 bytes: uint32 rdt_sequence (1, 2, ... within one stream: a gap is a lost
  record), uint32 ft_sequence (the sensor's internal sample number since power-up), uint32
  status (0 = healthy), int32 Fx, Fy, Fz, Tx, Ty, Tz in counts.
- Counts: force = counts / counts_per_force, torque = counts / counts_per_torque (the
  calibration's cfgcpf / cfgcpt, netftapi2.xml). With the units set to N and N m, a Net F/T
  with a Mini45 calibration reports 1,000,000 counts per N and per N m: the values used here.

Vehicle i's sensor (the simulator/companion contract): UDP 127.0.0.1:49152 + i. The sensor
frame is the end-effector frame {e}: Fx..Tz are wrench_E, the wrench the environment applies
on the end effector, expressed in {e} (amlink.types.SensorFrame.wrench_E).
"""
from __future__ import annotations

import struct
from typing import NamedTuple

RDT_PORT = 49152
COMMAND_HEADER = 0x1234
CMD_STOP, CMD_START_REALTIME, CMD_START_BUFFERED, CMD_START_MULTI_UNIT = 0x0000, 0x0002, 0x0003, 0x0004
CMD_RESET_THRESHOLD_LATCH, CMD_SET_SOFTWARE_BIAS = 0x0041, 0x0042
COMMANDS = (CMD_STOP, CMD_START_REALTIME, CMD_START_BUFFERED, CMD_START_MULTI_UNIT, CMD_RESET_THRESHOLD_LATCH,
            CMD_SET_SOFTWARE_BIAS)
COUNTS_PER_FORCE = 1_000_000  # counts per N
COUNTS_PER_TORQUE = 1_000_000  # counts per N m

_REQUEST = struct.Struct(">HHI")
_RECORD = struct.Struct(">III6i")
REQUEST_SIZE, RECORD_SIZE = _REQUEST.size, _RECORD.size  # 8, 36
_INT32 = (-(2 ** 31), 2 ** 31 - 1)


def netft_port(index: int) -> int:
    """The RDT port of vehicle `index`'s wrist sensor (0-based [[am]] order)."""
    return RDT_PORT + index


class Request(NamedTuple):
    command: int
    sample_count: int


class Record(NamedTuple):
    rdt_sequence: int
    ft_sequence: int
    status: int
    counts: tuple[int, int, int, int, int, int]  # Fx, Fy, Fz, Tx, Ty, Tz


def pack_request(command: int, sample_count: int = 0) -> bytes:
    return _REQUEST.pack(COMMAND_HEADER, command, sample_count)


def unpack_request(data: bytes) -> Request:
    """A request datagram; ValueError naming what is wrong (size, header)."""
    if len(data) != REQUEST_SIZE:
        raise ValueError(f"RDT request of {len(data)} bytes, expected {REQUEST_SIZE}")
    header, command, count = _REQUEST.unpack(data)
    if header != COMMAND_HEADER:
        raise ValueError(f"RDT request header {header:#06x}, expected {COMMAND_HEADER:#06x}")
    return Request(command, count)


def pack_record(rec: Record) -> bytes:
    return _RECORD.pack(rec.rdt_sequence & 0xFFFFFFFF, rec.ft_sequence & 0xFFFFFFFF, rec.status, *rec.counts)


def unpack_records(data: bytes) -> list[Record]:
    """The records of one datagram (one, or several in buffered mode); ValueError if its size
    is not a whole number of records."""
    if not data or len(data) % RECORD_SIZE:
        raise ValueError(f"RDT datagram of {len(data)} bytes is not a whole number of {RECORD_SIZE}-byte records")
    out = []
    for k in range(0, len(data), RECORD_SIZE):
        v = _RECORD.unpack_from(data, k)
        out.append(Record(v[0], v[1], v[2], tuple(v[3:9])))
    return out


def to_counts(wrench, counts_per_force: float = COUNTS_PER_FORCE,
              counts_per_torque: float = COUNTS_PER_TORQUE) -> tuple[int, ...]:
    """[Fx, Fy, Fz [N], Tx, Ty, Tz [N m]] as counts, rounded to the nearest and held in int32."""
    scale = (counts_per_force,) * 3 + (counts_per_torque,) * 3
    return tuple(min(max(int(round(float(w) * s)), _INT32[0]), _INT32[1]) for w, s in zip(wrench, scale))


def from_counts(counts, counts_per_force: float = COUNTS_PER_FORCE,
                counts_per_torque: float = COUNTS_PER_TORQUE) -> tuple[float, ...]:
    """Counts as [Fx, Fy, Fz [N], Tx, Ty, Tz [N m]] (the manual's "divide by counts per unit")."""
    return tuple(c / counts_per_force for c in counts[:3]) + tuple(c / counts_per_torque for c in counts[3:6])


def sequence_gap(previous: int, current: int) -> int:
    """Records lost between two rdt_sequence numbers, with the uint32 rollover; 0 if current
    follows previous, negative if it is not newer (a duplicate or a reordering)."""
    d = (current - previous) & 0xFFFFFFFF
    return d - 1 if d < 0x80000000 else d - 0x100000000 - 1
