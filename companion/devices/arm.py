"""The arm's DYNAMIXEL X-series servos in current control, through ROBOTIS's dynamixel-sdk
(PortHandler, PacketHandler(2.0), GroupSyncRead, GroupSyncWrite); the same code drives the
simulator's emulated bus (`simulator.servo_bus`) and a real one.

Endpoint (`parse_arm_endpoint`): ``tcp:HOST:PORT`` (the simulator's bus, or a serial-to-TCP
bridge; reached through pyserial's ``socket://`` URL with TCP_NODELAY) or ``DEVICE[:BAUD]``
(a U2D2 or any serial adapter, e.g. ``/dev/ttyUSB0:4000000``; 57600 baud, the X series'
factory Baud Rate(8) = 1, when not given).

`open()`: ping IDs 1..n (joint j -> ID j + 1; the model number names the servo and its
torque constant, `amlink.dxl_protocol.MODELS`), then on each servo Torque Enable 0,
Operating Mode 0 (current control), read its Current Limit, Goal Current 0, Torque Enable 1.
`read()`: one SYNC READ of Present Current, Velocity and Position (10 bytes from 126) ->
`JointSample` (q [rad], qdot [rad/s], tau_measured_nm = present current x K_t, t_ns taken
when the answer is in). `write_torques(tau_nm)`: one SYNC WRITE of Goal Current
round(tau / (K_t x 2.69 mA)), within each Current Limit. `close()`: with hold_on_close, each
servo goes back to position control holding where it is (Goal Position = Present Position),
so the arm holds rather than drops; then the port closes.

Errors (all `ArmError`, naming the endpoint): unreachable bus, `ServoNotAnswering` (no
status packet from an ID; the IDs that stayed silent are named), `ServoRefused` (a status
packet's error byte, in words), corrupt status packets (bad CRC or length; counted in
`stats.crc_errors`).
"""
from __future__ import annotations

import os
import re
import select
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import serial
from dynamixel_sdk import (COMM_RX_CORRUPT, COMM_RX_TIMEOUT, COMM_SUCCESS, GroupSyncRead, GroupSyncWrite,
                           PacketHandler, PortHandler)

from amlink import dxl_protocol as dxl
from amlink.endpoint import SERIAL, TCP_OUT, EndpointError, parse_endpoint

from . import DeviceError

DXL_DEFAULT_BAUD = 57600  # X series factory Baud Rate(8) = 1
READ_WAIT_S = 0.001  # TcpPortHandler.readPort's longest wait for bytes (the SDK re-checks its timeout after)
TCP_NOMINAL_BAUD = 4_000_000  # what the SDK's byte-time arithmetic assumes over TCP
_SDK_BAUDS = (9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600, 1000000, 1152000, 2000000,
              2500000, 3000000, 3500000, 4000000)  # PortHandler.getCFlagBaud's list (dynamixel-sdk 4.1.0)
ARM_FORMS = "accepted: tcp:HOST:PORT, or a serial DEVICE[:BAUD] such as /dev/ttyUSB0:4000000"


class ArmError(DeviceError):
    pass


class ServoNotAnswering(ArmError):
    def __init__(self, endpoint: str, ids) -> None:
        self.ids = tuple(ids)
        names = ", ".join(str(i) for i in self.ids)
        super().__init__(f"servo bus {endpoint}: no servo answering ID {names}")


class ServoRefused(ArmError):
    def __init__(self, endpoint: str, dxl_id: int, what: str, error: int) -> None:
        self.dxl_id, self.error = dxl_id, error
        super().__init__(f"servo bus {endpoint}: ID {dxl_id} refused {what}: {dxl.error_text(error)}")


@dataclass(frozen=True)
class ArmEndpoint:
    kind: str  # "tcp" or "serial"
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0

    def __str__(self) -> str:
        return f"tcp:{self.host}:{self.port}" if self.kind == "tcp" else f"{self.device}:{self.baud}"


def parse_arm_endpoint(text: str) -> ArmEndpoint:
    """``tcp:HOST:PORT`` or ``DEVICE[:BAUD]``; ValueError naming what is wrong."""
    try:
        ep = parse_endpoint(text)
    except EndpointError as e:
        raise ValueError(f"--arm {text!r}: {e.why}; {ARM_FORMS}") from None
    if ep.kind == TCP_OUT:
        return ArmEndpoint("tcp", host=ep.host, port=ep.port)
    if ep.kind == SERIAL:
        baud = ep.baud if re.search(r"[:,]\d+$", text.strip()) else DXL_DEFAULT_BAUD
        if baud not in _SDK_BAUDS:
            raise ValueError(f"--arm {text!r}: dynamixel-sdk opens {', '.join(map(str, _SDK_BAUDS))} baud, not {baud}")
        return ArmEndpoint("serial", device=ep.device, baud=baud)
    raise ValueError(f"--arm {text!r}: a servo bus is not reached by {ep.kind}; {ARM_FORMS}")


class TcpPortHandler(PortHandler):
    """dynamixel-sdk's PortHandler on a TCP stream: pyserial's ``socket://`` in place of a tty."""

    def __init__(self, host: str, port: int) -> None:
        super().__init__(f"socket://{host}:{port}")

    def setupPort(self, cflag_baud):  # noqa: N802 (the SDK's name)
        if self.is_open:
            self.closePort()
        self.ser = serial.serial_for_url(self.port_name, timeout=0)
        with socket.socket(fileno=os.dup(self.ser.fileno())) as s:  # Nagle would hold a packet for an ACK
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True

    def readPort(self, length):  # noqa: N802 (the SDK's name)
        """As the SDK's, but waiting up to READ_WAIT_S for bytes instead of returning none at once:
        the SDK polls readPort in a loop until its packet timeout, which on a socket that has
        nothing yet spins a core the simulator (or the rest of the companion) needs."""
        if not self.ser.in_waiting:
            select.select([self.ser.fileno()], [], [], READ_WAIT_S)
        return self.ser.read(length)


@dataclass(frozen=True)
class JointSample:
    """One read of the arm: q [rad], qdot [rad/s], tau_measured_nm [N m] (present current x
    K_t), per joint; t_ns: the client's clock when the answer was in; rtt_ns: the read's
    round trip."""

    q: np.ndarray
    qdot: np.ndarray
    tau_measured_nm: np.ndarray
    t_ns: int
    rtt_ns: int


@dataclass
class ArmStats:
    reads: int = 0
    writes: int = 0
    crc_errors: int = 0  # corrupt status packets (bad CRC or length)
    timeouts: int = 0  # no status packet in the SDK's packet timeout
    tx_errors: int = 0


def _signed(v: int, bits: int) -> int:
    return v - (1 << bits) if v & (1 << (bits - 1)) else v


class ArmClient:
    """The arm's servos (module doc). n_joints servos with IDs 1..n; clock: a monotonic
    nanosecond clock; hold_on_close: leave the servos holding in position control."""

    def __init__(self, endpoint: str, n_joints: int, *, clock: Callable[[], int] = time.monotonic_ns,
                 hold_on_close: bool = True) -> None:
        self.ep = parse_arm_endpoint(endpoint)
        if not 1 <= n_joints <= dxl.MAX_ID:
            raise ValueError(f"n_joints = {n_joints}: 1..{dxl.MAX_ID} servos")
        self.ids = [dxl.joint_id(j) for j in range(n_joints)]
        self.clock, self.hold_on_close = clock, hold_on_close
        self.stats = ArmStats()
        self.models: list[dxl.ServoModel] = []
        self.current_limit_units = np.zeros(n_joints, dtype=int)
        self._nm_per_unit = np.zeros(n_joints)
        self._port: PortHandler | None = None
        self._ph = PacketHandler(2.0)
        self._sync_read: GroupSyncRead | None = None
        self._sync_write: GroupSyncWrite | None = None
        self._torque_on = False
        self._request_ns: int | None = None  # a sync read's instruction out since then (request)

    @property
    def torque_limits_nm(self) -> np.ndarray:
        """Each servo's Current Limit as a torque [N m] (after `open`)."""
        return self.current_limit_units * self._nm_per_unit

    def open(self, current_control: bool = True) -> None:
        """Reach the bus, find every servo, switch them to current control (module doc); with
        current_control False they keep what they do (a powered-up X servo: holding its
        position) until `start_current_control`, so that an arm waits on the ground holding."""
        if self.ep.kind == "tcp":
            port = TcpPortHandler(self.ep.host, self.ep.port)
            baud = TCP_NOMINAL_BAUD
        else:
            port = PortHandler(self.ep.device)
            baud = self.ep.baud
        try:
            ok = port.setBaudRate(baud)
        except (serial.SerialException, OSError) as e:
            raise ArmError(f"servo bus {self.ep} unreachable: {e}") from None
        if not ok:
            raise ArmError(f"servo bus {self.ep}: the SDK refused {baud} baud")
        self._port = port
        try:
            self._find_servos()
            if current_control:
                self._current_control()
        except BaseException:
            self._port.closePort()
            self._port = None
            raise
        self._sync_read = GroupSyncRead(port, self._ph, *dxl.PRESENT_BLOCK)
        self._sync_write = GroupSyncWrite(port, self._ph, dxl.ADDR_GOAL_CURRENT, 2)
        for i in self.ids:
            self._sync_read.addParam(i)

    def _lost(self, what: str, exc: Exception) -> ArmError:
        """The error of a transaction the bus broke off (the simulator ended, a cable pulled). The
        SDK leaves its transaction flag set on an exception; cleared here, so that the next
        call reports its own error, not "Port is in use!"."""
        self._port.is_using = False
        return ArmError(f"servo bus {self.ep}: {what}: {exc}")

    def _count(self, result: int) -> None:
        if result == COMM_RX_CORRUPT:
            self.stats.crc_errors += 1
        elif result == COMM_RX_TIMEOUT:
            self.stats.timeouts += 1
        elif result != COMM_SUCCESS:
            self.stats.tx_errors += 1

    def _find_servos(self) -> None:
        missing, models = [], []
        for i in self.ids:
            for _ in range(2):  # once more after a corrupt answer
                number, result, error = self._ph.ping(self._port, i)
                self._count(result)
                if result != COMM_RX_CORRUPT:
                    break
            if result == COMM_RX_CORRUPT:
                raise ArmError(f"servo bus {self.ep}: ID {i} answered PING with corrupt status packets")
            if result != COMM_SUCCESS:
                missing.append(i)
                continue
            model = dxl.MODELS.get(number)
            if model is None:
                known = ", ".join(f"{m.model_number} ({m.name})" for m in dxl.MODELS.values())
                raise ArmError(f"servo bus {self.ep}: ID {i} is model number {number}, not one this client knows "
                               f"the torque constant of: {known}")
            models.append(model)
        if missing:
            raise ServoNotAnswering(str(self.ep), missing)
        self.models = models
        self._nm_per_unit = np.array([m.nm_per_current_unit for m in models])

    def _txrx(self, what: str, dxl_id: int, result: int, error: int) -> None:
        self._count(result)
        if result == COMM_RX_TIMEOUT:
            raise ServoNotAnswering(str(self.ep), [dxl_id])
        if result != COMM_SUCCESS:
            raise ArmError(f"servo bus {self.ep}: ID {dxl_id}, {what}: {self._ph.getTxRxResult(result)}")
        if error & 0x7F:
            raise ServoRefused(str(self.ep), dxl_id, what, error)

    def _write1(self, i: int, address: int, value: int, what: str) -> None:
        self._txrx(what, i, *self._ph.write1ByteTxRx(self._port, i, address, value))

    def start_current_control(self) -> None:
        """Switch every servo to current control with Goal Current 0 (after `open(current_control=False)`)."""
        if self._port is None:
            raise ArmError(f"servo bus {self.ep}: not open")
        if not self._torque_on:
            self._current_control()

    def _current_control(self) -> None:
        ph, port = self._ph, self._port
        for k, i in enumerate(self.ids):
            self._write1(i, dxl.ADDR_TORQUE_ENABLE, 0, "Torque Enable = 0")
            self._write1(i, dxl.ADDR_OPERATING_MODE, dxl.MODE_CURRENT, "Operating Mode = 0 (current)")
            limit, result, error = ph.read2ByteTxRx(port, i, dxl.ADDR_CURRENT_LIMIT)
            self._txrx("read Current Limit", i, result, error)
            self.current_limit_units[k] = limit
            self._txrx("Goal Current = 0", i, *ph.write2ByteTxRx(port, i, dxl.ADDR_GOAL_CURRENT, 0))
            self._write1(i, dxl.ADDR_TORQUE_ENABLE, 1, "Torque Enable = 1")
        self._torque_on = True

    def read(self) -> JointSample:
        """One SYNC READ of every servo's present current, velocity and position (`request`
        then `collect`)."""
        self.request()
        return self.collect()

    @property
    def requested(self) -> bool:
        """Whether a sync read's instruction is out and its answers not yet collected."""
        return self._request_ns is not None

    def request(self) -> None:
        """Send the SYNC READ instruction, without waiting for the answers: the servos answer
        while the caller does other work, and `collect` takes them (a bus with one master: the
        next instruction must wait for `collect`). A request already out is collected first."""
        if self._sync_read is None:
            raise ArmError(f"servo bus {self.ep}: not open")
        if self._request_ns is not None:
            self.collect()
        t0 = self.clock()
        try:
            result = self._sync_read.txPacket()
        except (serial.SerialException, OSError) as e:  # the bus went away (the simulator ended, a cable)
            raise self._lost("sync read", e) from None
        if result != COMM_SUCCESS:
            self._count(result)
            raise ArmError(f"servo bus {self.ep}: sync read: {self._ph.getTxRxResult(result)}")
        self._request_ns = t0

    def collect(self) -> JointSample:
        """The answers to the SYNC READ `request` sent (one is sent now if none is out) as a
        JointSample: t_ns when the last answer was in, rtt_ns from the request."""
        if self._sync_read is None:
            raise ArmError(f"servo bus {self.ep}: not open")
        if self._request_ns is None:
            self.request()
        t0, self._request_ns = self._request_ns, None
        try:
            result = self._sync_read.rxPacket()
        except (serial.SerialException, OSError) as e:
            raise self._lost("sync read", e) from None
        t_ns = self.clock()
        self._count(result)
        if result != COMM_SUCCESS:
            if result == COMM_RX_TIMEOUT:
                raise ServoNotAnswering(str(self.ep), self._silent_ids())
            raise ArmError(f"servo bus {self.ep}: sync read: {self._ph.getTxRxResult(result)}")
        self.stats.reads += 1
        n = len(self.ids)
        cur, vel, pos = np.empty(n), np.empty(n), np.empty(n)
        for k, i in enumerate(self.ids):
            g = self._sync_read.getData
            cur[k] = _signed(g(i, dxl.ADDR_PRESENT_CURRENT, 2), 16)
            vel[k] = _signed(g(i, dxl.ADDR_PRESENT_VELOCITY, 4), 32)
            pos[k] = _signed(g(i, dxl.ADDR_PRESENT_POSITION, 4), 32)
        return JointSample((pos - dxl.CENTER_PULSE) * dxl.RAD_PER_PULSE, vel * dxl.RADPS_PER_VELOCITY_UNIT,
                           cur * self._nm_per_unit, t_ns, t_ns - t0)

    def _silent_ids(self) -> list[int]:
        silent = [i for i in self.ids if self._ph.ping(self._port, i)[1] != COMM_SUCCESS]
        return silent or list(self.ids)

    def write_torques(self, tau_nm) -> np.ndarray:
        """One SYNC WRITE of Goal Current for joint torques tau_nm [N m]; returns the torques
        the written currents stand for (rounded to one unit, within each Current Limit)."""
        if self._sync_write is None:
            raise ArmError(f"servo bus {self.ep}: not open")
        tau = np.asarray(tau_nm, dtype=float)
        if tau.shape != (len(self.ids),) or not np.all(np.isfinite(tau)):
            raise ValueError(f"tau_nm must be {len(self.ids)} finite torques, got {tau_nm!r}")
        units = np.clip(np.round(tau / self._nm_per_unit), -self.current_limit_units, self.current_limit_units)
        w = self._sync_write
        w.clearParam()
        for i, u in zip(self.ids, units.astype(int)):
            w.addParam(i, list(int(u).to_bytes(2, "little", signed=True)))
        try:
            result = w.txPacket()
        except (serial.SerialException, OSError) as e:
            raise self._lost("sync write", e) from None
        self._count(result)
        if result != COMM_SUCCESS:
            raise ArmError(f"servo bus {self.ep}: sync write: {self._ph.getTxRxResult(result)}")
        self.stats.writes += 1
        return units * self._nm_per_unit

    def close(self) -> None:
        """Leave the servos holding in position control (hold_on_close), close the port."""
        if self._port is None:
            return
        if self._request_ns is not None:  # answers still on their way: take them off the bus first
            try:
                self.collect()
            except ArmError:
                pass
        try:
            if self.hold_on_close and self._torque_on:
                ph, port = self._ph, self._port
                for i in self.ids:
                    self._txrx("Goal Current = 0", i, *ph.write2ByteTxRx(port, i, dxl.ADDR_GOAL_CURRENT, 0))
                    self._write1(i, dxl.ADDR_TORQUE_ENABLE, 0, "Torque Enable = 0")
                    self._write1(i, dxl.ADDR_OPERATING_MODE, dxl.MODE_POSITION, "Operating Mode = 3 (position)")
                    pos, result, error = ph.read4ByteTxRx(port, i, dxl.ADDR_PRESENT_POSITION)
                    self._txrx("read Present Position", i, result, error)
                    self._txrx("Goal Position", i, *ph.write4ByteTxRx(port, i, dxl.ADDR_GOAL_POSITION, pos))
                    self._write1(i, dxl.ADDR_TORQUE_ENABLE, 1, "Torque Enable = 1")
        except (serial.SerialException, OSError) as e:  # the bus went away: the hold cannot be set
            raise ArmError(f"servo bus {self.ep}: hold on close: {e}") from None
        finally:
            self._torque_on = False
            self._port.closePort()
            self._port = None
            self._sync_read = self._sync_write = None
