"""Emulated DYNAMIXEL X-series servos and the bus that answers their instruction packets
(pure: numpy and amlink.dxl_protocol; no sockets; `simulator.servo_bus` moves the bytes).

`XServo` is one servo: its control table (amlink.dxl_protocol.FIELDS, the XM430-W350 /
XM540-W270 e-Manual tables) with the servo's rules for writes, the torque it applies, and
the present values it reports.

Writes (protocol2.md's error numbers): a write touching an undefined or read-only address,
or the EEPROM area (addresses < 64) while Torque Enable is 1, is refused whole with the
Access error (0x07: "Attempt to write a value in the ROM domain while in a state of Torque
Enable (ROM Lock)"); one covering part of an item, the Data Length error (0x05); a value
outside the item's range, the Data Range error (0x04); Goal Current beyond Current Limit,
Goal PWM beyond PWM Limit, Goal Velocity beyond Velocity Limit, Goal Position outside the
Min/Max Position Limits (position mode), the Data Limit error (0x06). Reads of any range
inside addresses 0..146 answer (unused bytes read 0); beyond, the Access error.

Power-up (and REBOOT): Startup Configuration(60) is 1 ("Startup Torque On", X-series
firmware v45+, e-Manual control_table_60_startup_configuration), so the servo boots with
Torque Enable 1 in Position Control Mode (Operating Mode 3, the initial value) with Goal
Position = its present position: an arm nobody commands holds its start pose. The factory
value is 0 (torque off); this is the integrator's setting. Goal Current boots at 0 and Goal
PWM at PWM Limit (our choice where the e-Manual gives "-"). Current Limit is set from the
joint's torque limit (the integrator's EEPROM setting), else the model's initial value.
Torque Enable 0 -> 1 sets Goal Position to Present Position, so enabling torque never jumps
(our choice; the e-Manual does not say).

The torque the servo applies (`torque_nm(q, qdot)`), with the motor at 12 V as a DC motor:
current i = I_stall (d - qdot / w_0) for a duty d in [-1, 1] (d = PWM / 885), I_stall and the
no-load speed w_0 from the model's e-Manual specification, torque = K_t i with
K_t = stall torque / stall current (XM540-W270: 2.409 N m/A, the e-Manual's figure and the
one simulator/devices.py's JointEffortSensor uses), |i| <= Current Limit x 2.69 mA.
- Torque Enable 0: no torque.
- Current Control Mode (0): i = Goal Current x 2.69 mA (within Current Limit), as far as the
  duty (|d| <= Goal PWM / 885) can drive it at this speed.
- Position Control Mode (3) and Extended Position Control Mode (4): the e-Manual's position
  PID (control_table_position_pid_gain: K_P P = P(84) / 128, K_P I = I(82) / 65536,
  K_P D = D(80) / 16, defaults 800, 0, 0) on e = Goal Position - Present Position [pulse]
  gives the PWM [units of 0.113 %], limited by Goal PWM. The e-Manual does not give the
  controller's period: we take 1 ms, so that the D term acts on de/dt in pulse/ms and the I
  term sums e over each ms (both 0 at the defaults); the integral is clamped to the PWM range
  (the e-Manual's anti-windup gain K_a is not published). The result is limited by Current
  Limit as stated above (the firmware limits PWM in this mode; the current limit here stands
  for its overload protection). No profile: Profile Velocity / Acceleration are stored and
  the goal is followed directly (their initial value 0 means no profile).
- PWM Control Mode (16): d = Goal PWM / 885.
Velocity (1) and Current-based Position (5) modes are refused (Data Range error): not
emulated. Stored, not emulated: Drive Mode, Bus Watchdog, Return Delay Time (answers go out
in the poll that read the instruction), Secondary ID, indirect addresses (not in the table).

What the next read returns (`observe(t_s, q, qdot, tau_nm)`): Present Position (2048 = 0 rad,
plus Homing Offset), Present Velocity (0.229 rev/min units), Present Current: the applied
torque / K_t through [devices.effort]'s first-order lag (lag_s, over the time between
observations) and white noise (noise_nm, scaled by [devices].scale, in current units; drawn
when a read first takes the observation, one draw per observation read, so a servo nobody
reads costs no draws), rounded to one current unit (the register's own quantum: 6.48 mN m for the XM540-W270, the
resolution_nm of configs/randomize/default.toml), Present PWM, Realtime Tick, Moving,
Present Input Voltage 12.0 V and Present Temperature 36 degC (constants).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from amcore.config import JointEffortSpec
from amlink import dxl_protocol as dxl
from amlink.dxl_protocol import FIELDS, R, TABLE_SIZE, Field, ServoModel

_AT = {f.address: f for f in FIELDS}
_SORTED = sorted(FIELDS, key=lambda f: f.address)
_INSIDE = {f.address + k: f for f in FIELDS for k in range(1, f.size)}
_EMULATED_MODES = (dxl.MODE_CURRENT, dxl.MODE_POSITION, dxl.MODE_EXTENDED_POSITION, dxl.MODE_PWM)
_VALID_MODES = (0, 1, 3, 4, 5, 16)
_STREAM = 0xD71  # the servos' generator stream, apart from the AM's other devices
CONTROL_PERIOD_MS = 1.0  # our reading of the position PID's period (module doc)
INPUT_VOLTAGE_UNITS = 120  # 12.0 V
TEMPERATURE_C = 36

# RAM items' initial values (e-Manual tables); Goal Position is the present position
_RAM_INIT = {"led": 0, "status_return_level": 2, "registered_instruction": 0, "hardware_error_status": 0,
             "velocity_i_gain": 1920, "velocity_p_gain": 100, "position_d_gain": 0, "position_i_gain": 0,
             "position_p_gain": 800, "feedforward_2nd_gain": 0, "feedforward_1st_gain": 0, "bus_watchdog": 0,
             "goal_current": 0, "goal_velocity": 0, "profile_acceleration": 0, "profile_velocity": 0}


@functools.lru_cache(maxsize=256)
def _layout(address: int, length: int) -> tuple[tuple[Field, slice, slice], ...]:
    """The items a read of [address, address + length) covers: (item, its bytes, where they go)."""
    out = []
    for f in _SORTED:
        lo, hi = max(address, f.address), min(address + length, f.address + f.size)
        if lo < hi:
            out.append((f, slice(lo - f.address, hi - f.address), slice(lo - address, hi - address)))
    return tuple(out)


class XServo:
    """One emulated X-series servo (module doc). `dxl_id` 1..252; `q0_rad` the joint angle at
    power-up; `current_limit` Current Limit(38) [units of 2.69 mA] (None: the model's
    initial value); `effort` the Present Current reading's lag and noise; `rng` its draws."""

    def __init__(self, dxl_id: int, model: ServoModel, q0_rad: float = 0.0, current_limit: int | None = None,
                 effort: JointEffortSpec = JointEffortSpec(), noise_scale: float = 1.0,
                 rng: np.random.Generator | None = None) -> None:
        if not 0 <= dxl_id <= dxl.MAX_ID:
            raise ValueError(f"servo ID {dxl_id} is not in 0..{dxl.MAX_ID}")
        limit = model.current_limit_max if current_limit is None else int(current_limit)
        if not 0 <= limit <= model.current_limit_max:
            raise ValueError(f"Current Limit {limit} is not in 0..{model.current_limit_max} ({model.name})")
        self.model = model
        self.v = {f.name: 0 for f in FIELDS}  # the control table's values (bytes formed when read)
        self._lag_s = effort.lag_s
        self._noise_units = noise_scale * effort.noise_nm / model.nm_per_current_unit
        self._rng = rng if rng is not None else np.random.default_rng(0)
        self._draws, self._di = np.empty(0), 0  # the noise's draws, taken in blocks
        self._stale = False  # an observation not yet turned into the present values (`_refresh`)
        self._obs = (0.0, 0.0, 0.0)  # the last observation: t [s], q [rad], qdot [rad/s]
        self._lag_dt, self._lag_a = -1.0, 0.0  # the lag's last step and its gain, -expm1(-dt / lag_s)
        eeprom = {"model_number": model.model_number, "model_information": 0,
                  "firmware_version": model.firmware_version, "id": dxl_id, "baud_rate": 1, "return_delay_time": 250,
                  "drive_mode": 0, "operating_mode": dxl.MODE_POSITION, "secondary_id": 255, "protocol_type": 2,
                  "homing_offset": 0, "moving_threshold": 10, "temperature_limit": 80, "max_voltage_limit": 160,
                  "min_voltage_limit": 95, "pwm_limit": dxl.PWM_FULL, "current_limit": limit,
                  "acceleration_limit": 32767, "velocity_limit": model.velocity_limit_init,
                  "max_position_limit": 4095, "min_position_limit": 0, "startup_configuration": 1, "shutdown": 52}
        for name, v in eeprom.items():
            self._set(name, v)
        self.power_up(q0_rad)

    # -- the control table ------------------------------------------------------------
    def get(self, name: str) -> int:
        if self._stale:
            self._refresh()
        return self.v[name]

    def _set(self, name: str, value: int) -> None:
        self.v[name] = int(value)

    @property
    def mem(self) -> bytes:
        """The whole control table as bytes (addresses 0..146)."""
        return self.read(0, TABLE_SIZE)[1]

    @property
    def dxl_id(self) -> int:
        return self.v["id"]

    @property
    def torque_on(self) -> bool:
        return self.v["torque_enable"] == 1

    def power_up(self, q_rad: float, qdot_radps: float = 0.0) -> None:
        """The RAM area as the servo boots with the joint at q_rad (module doc)."""
        for name, v in _RAM_INIT.items():
            self._set(name, v)
        self._set("goal_pwm", self.get("pwm_limit"))
        self._x_units: float | None = None  # the lagged current [units]
        self._t_last: float | None = None
        self._integral = 0.0  # pulse ms
        self._duty = 0.0
        self.observe(0.0, q_rad, qdot_radps, 0.0)
        self._t_last = None
        self._set("goal_position", self.get("present_position"))
        self._set("torque_enable", self.get("startup_configuration") & 1)

    def read(self, address: int, length: int) -> tuple[int, bytes]:
        """(error, data) of a READ of `length` bytes from `address`."""
        if length <= 0:
            return dxl.ERR_DATA_LENGTH, b""
        if address < 0 or address + length > TABLE_SIZE:
            return dxl.ERR_ACCESS, b""
        if self._stale:
            self._refresh()
        out = bytearray(length)
        for f, src, dst in _layout(address, length):
            out[dst] = f.encode(self.v[f.name])[src]
        return dxl.ERR_NONE, bytes(out)

    def write(self, address: int, data: bytes) -> int:
        """A WRITE of `data` from `address`: its error number (0: written). All or nothing."""
        end = address + len(data)
        if not data:
            return dxl.ERR_DATA_LENGTH
        fields: list[Field] = []
        a = address
        while a < end:
            f = _AT.get(a)
            if f is None:
                return dxl.ERR_DATA_LENGTH if a in _INSIDE else dxl.ERR_ACCESS
            if f.access == R or (f.eeprom and self.torque_on):
                return dxl.ERR_ACCESS
            if a + f.size > end:
                return dxl.ERR_DATA_LENGTH
            fields.append(f)
            a += f.size
        values = [(f, f.decode(data[f.address - address:f.address - address + f.size])) for f in fields]
        for f, v in values:
            err = self._check(f, v)
            if err:
                return err
        for f, v in values:
            was_on = self.torque_on
            self.v[f.name] = v
            if f.name == "torque_enable" and v == 1 and not was_on:
                # from the present position, not toward a goal left from before (our choice)
                self._set("goal_position", self.get("present_position"))
                self._integral = 0.0
        return dxl.ERR_NONE

    def _check(self, f: Field, v: int) -> int:
        if not f.lo <= v <= f.hi:
            return dxl.ERR_DATA_RANGE
        name = f.name
        if name == "operating_mode" and (v not in _VALID_MODES or v not in _EMULATED_MODES):
            return dxl.ERR_DATA_RANGE
        if name == "current_limit" and v > self.model.current_limit_max:
            return dxl.ERR_DATA_RANGE
        if name == "goal_current" and abs(v) > self.get("current_limit"):
            return dxl.ERR_DATA_LIMIT
        if name == "goal_pwm" and abs(v) > self.get("pwm_limit"):
            return dxl.ERR_DATA_LIMIT
        if name == "goal_velocity" and abs(v) > self.get("velocity_limit"):
            return dxl.ERR_DATA_LIMIT
        if name == "goal_position" and self.get("operating_mode") == dxl.MODE_POSITION \
                and not self.get("min_position_limit") <= v <= self.get("max_position_limit"):
            return dxl.ERR_DATA_LIMIT
        return dxl.ERR_NONE

    # -- the motor ----------------------------------------------------------------------
    def present_pulse(self, q_rad: float) -> int:
        return dxl.CENTER_PULSE + int(round(q_rad / dxl.RAD_PER_PULSE)) + self.v["homing_offset"]

    def _position_pwm(self, q_rad: float, qdot_radps: float) -> float:
        v = self.v
        e = v["goal_position"] - self.present_pulse(q_rad)
        e_dot = -qdot_radps / dxl.RAD_PER_PULSE * 1e-3 * CONTROL_PERIOD_MS  # pulse per control period
        return (v["position_p_gain"] / 128.0 * e + v["position_d_gain"] / 16.0 * e_dot
                + v["position_i_gain"] / 65536.0 * self._integral)

    def torque_nm(self, q_rad: float, qdot_radps: float) -> float:
        """The torque the servo applies now [N m] at joint angle q and rate qdot (module doc)."""
        v = self.v
        if v["torque_enable"] != 1:
            self._duty = 0.0
            return 0.0
        m = self.model
        i_stall = m.stall_current_a
        w = qdot_radps / m.no_load_speed_radps
        d_max = min(abs(v["goal_pwm"]), v["pwm_limit"]) / dxl.PWM_FULL
        i_max = v["current_limit"] * dxl.AMPS_PER_CURRENT_UNIT
        mode = v["operating_mode"]
        if mode == dxl.MODE_CURRENT:
            i = min(max(v["goal_current"] * dxl.AMPS_PER_CURRENT_UNIT, -i_max), i_max)
            i = min(max(i, i_stall * (-d_max - w)), i_stall * (d_max - w))  # the duty it takes
            self._duty = i / i_stall + w
        else:
            pwm = v["goal_pwm"] if mode == dxl.MODE_PWM else self._position_pwm(q_rad, qdot_radps)
            self._duty = min(max(pwm / dxl.PWM_FULL, -d_max), d_max)
            i = min(max(i_stall * (self._duty - w), -i_max), i_max)
        return m.torque_constant_nm_per_a * i

    def observe(self, t_s: float, q_rad: float, qdot_radps: float, tau_nm: float) -> None:
        """The present values after time t_s [s] with the joint at q, qdot and the servo
        applying tau_nm (module doc). Called every physics step, it does only what must
        follow every step (the current's lag, the position integral); the registers are
        formed from the last observation when something reads them (`_refresh`), and the
        reading's white noise is drawn then, one draw per observation read."""
        v = self.v
        dt = 0.0 if self._t_last is None else max(0.0, t_s - self._t_last)
        self._t_last = t_s
        self._obs = (t_s, q_rad, qdot_radps)
        self._stale = True
        u = tau_nm / self.model.nm_per_current_unit
        if self._x_units is None or self._lag_s <= 0.0:
            self._x_units = u
        else:
            if dt != self._lag_dt:  # a fixed physics step: the gain is computed once
                self._lag_dt, self._lag_a = dt, -math.expm1(-dt / self._lag_s)
            self._x_units += self._lag_a * (u - self._x_units)
        if v["torque_enable"] == 1 and v["operating_mode"] in (dxl.MODE_POSITION, dxl.MODE_EXTENDED_POSITION):
            pos = min(max(self.present_pulse(q_rad), -2**31), 2**31 - 1)
            ki = v["position_i_gain"] / 65536.0
            self._integral += (v["goal_position"] - pos) * dt * 1000.0 / CONTROL_PERIOD_MS
            if ki > 0.0:
                lim = dxl.PWM_FULL / ki
                self._integral = min(max(self._integral, -lim), lim)
        else:
            self._integral = 0.0

    def _refresh(self) -> None:
        """The present-value registers from the last observation (`observe`)."""
        self._stale = False
        v = self.v
        t_s, q_rad, qdot_radps = self._obs
        pos = min(max(self.present_pulse(q_rad), -2**31), 2**31 - 1)
        vel = min(max(dxl.radps_to_velocity(qdot_radps), -2**31), 2**31 - 1)
        v["present_position"], v["present_velocity"] = pos, vel
        y = self._x_units + (self._noise_units * self._draw() if self._noise_units > 0.0 else 0.0)
        v["present_current"] = min(max(int(round(y)), -32768), 32767)
        v["present_pwm"] = int(round(self._duty * dxl.PWM_FULL))
        v["realtime_tick"] = int(t_s * 1000.0) % 32768
        v["moving"] = 1 if abs(vel) > v["moving_threshold"] else 0
        v["position_trajectory"] = v["goal_position"]
        v["present_input_voltage"], v["present_temperature"] = INPUT_VOLTAGE_UNITS, TEMPERATURE_C

    def _draw(self) -> float:
        if self._di == self._draws.shape[0]:
            self._draws, self._di = self._rng.standard_normal(256), 0
        self._di += 1
        return float(self._draws[self._di - 1])

    @property
    def error_byte(self) -> int:
        """The status packet's error byte before the instruction's own error: the Alert bit."""
        return dxl.ERR_ALERT if self.get("hardware_error_status") else 0


@dataclass
class BusStats:
    """Counters of one emulated bus."""

    packets: int = 0
    crc_errors: int = 0  # instruction packets whose CRC did not match
    unsupported: int = 0  # instructions not emulated (answered with the Instruction error)
    malformed: int = 0  # parameters of the wrong length
    write_errors: int = 0  # writes refused (all instructions)
    no_such_id: int = 0  # unicast packets to an ID nobody on this bus has


class DxlBus:
    """The servos on one bus answering instruction packets: `handle(packet) -> bytes` gives
    the status packets the servos send back, in the order they send them (protocol2.md: one
    per servo for PING to the broadcast ID, SYNC READ and BULK READ, in the order of the
    IDs in the instruction; none for broadcast WRITE, SYNC WRITE, BULK WRITE). Status
    Return Level(68): 0 answers PING only, 1 also READ (and SYNC/BULK READ), 2 all. A packet
    with a bad CRC is answered by the servo it names with the CRC error (0x03)."""

    def __init__(self, servos: list[XServo]) -> None:
        self.servos = list(servos)
        self.stats = BusStats()

    def servo(self, dxl_id: int) -> XServo | None:
        for s in self.servos:
            if s.dxl_id == dxl_id:
                return s
        return None

    def _status(self, s: XServo, error: int, params: bytes = b"", *, read: bool = False, ping: bool = False) -> bytes:
        level = s.get("status_return_level")
        if not (ping or level >= 2 or (read and level >= 1)):
            return b""
        return dxl.status(s.dxl_id, s.error_byte | error, params)

    def handle(self, pkt: dxl.Packet) -> bytes:
        self.stats.packets += 1
        broadcast = pkt.dxl_id == dxl.BROADCAST_ID
        s = None if broadcast else self.servo(pkt.dxl_id)
        if not broadcast and s is None:
            self.stats.no_such_id += 1
            if not pkt.crc_ok:
                self.stats.crc_errors += 1
            return b""
        if not pkt.crc_ok:
            self.stats.crc_errors += 1
            return b"" if broadcast else dxl.status(s.dxl_id, s.error_byte | dxl.ERR_CRC)
        inst, p = pkt.inst, pkt.params
        if inst == dxl.PING:
            targets = sorted(self.servos, key=lambda x: x.dxl_id) if broadcast else [s]
            return b"".join(self._status(t, 0, dxl.BY_NAME["model_number"].encode(t.get("model_number"))
                                         + bytes((t.get("firmware_version"),)), ping=True) for t in targets)
        if inst == dxl.READ:
            if broadcast:
                return b""
            if len(p) != 4:
                self.stats.malformed += 1
                return self._status(s, dxl.ERR_DATA_LENGTH, read=True)
            err, data = s.read(p[0] | p[1] << 8, p[2] | p[3] << 8)
            return self._status(s, err, data, read=True)
        if inst == dxl.WRITE:
            if len(p) < 3:
                self.stats.malformed += 1
                return b"" if broadcast else self._status(s, dxl.ERR_DATA_LENGTH)
            addr, data = p[0] | p[1] << 8, p[2:]
            if broadcast:
                for t in self.servos:
                    self.stats.write_errors += 1 if t.write(addr, data) else 0
                return b""
            err = s.write(addr, data)
            self.stats.write_errors += 1 if err else 0
            return self._status(s, err)
        if inst in (dxl.SYNC_READ, dxl.SYNC_WRITE, dxl.BULK_READ, dxl.BULK_WRITE) and broadcast:
            return self._group(inst, p)
        if inst == dxl.REBOOT and not broadcast:
            out = self._status(s, 0)
            s.power_up(dxl.pulse_to_rad(s.get("present_position") - s.get("homing_offset")))
            return out
        self.stats.unsupported += 1
        return b"" if broadcast else self._status(s, dxl.ERR_INSTRUCTION)

    def _group(self, inst: int, p: bytes) -> bytes:
        out = []
        if inst in (dxl.SYNC_READ, dxl.SYNC_WRITE):
            if len(p) < 4:
                self.stats.malformed += 1
                return b""
            addr, n = p[0] | p[1] << 8, p[2] | p[3] << 8
            if inst == dxl.SYNC_READ:
                for i in p[4:]:
                    t = self.servo(i)
                    if t is not None:
                        out.append(self._status(t, *t.read(addr, n), read=True))
                return b"".join(out)
            body = p[4:]
            if n == 0 or len(body) % (n + 1):
                self.stats.malformed += 1
                return b""
            for k in range(0, len(body), n + 1):
                t = self.servo(body[k])
                if t is not None:
                    self.stats.write_errors += 1 if t.write(addr, body[k + 1:k + 1 + n]) else 0
            return b""
        k = 0
        while k + 5 <= len(p):
            i, addr, n = p[k], p[k + 1] | p[k + 2] << 8, p[k + 3] | p[k + 4] << 8
            t = self.servo(i)
            if inst == dxl.BULK_READ:
                if t is not None:
                    out.append(self._status(t, *t.read(addr, n), read=True))
                k += 5
            else:
                if k + 5 + n > len(p):
                    break
                if t is not None:
                    self.stats.write_errors += 1 if t.write(addr, p[k + 5:k + 5 + n]) else 0
                k += 5 + n
        if k != len(p):
            self.stats.malformed += 1
        return b"".join(out)


class BusPort:
    """One way onto the bus (a TCP client, a pty): bytes in, the servos' answers out."""

    def __init__(self, bus: DxlBus) -> None:
        self.bus = bus
        self.parser = dxl.PacketParser()

    def feed(self, data: bytes) -> bytes:
        return b"".join(self.bus.handle(pkt) for pkt in self.parser.feed(data))


def servo_rng(seed: int, sysid: int, dxl_id: int) -> np.random.Generator:
    """Servo `dxl_id`'s own generator (scenario seed, sysid, this device's stream)."""
    return np.random.default_rng([seed, sysid, _STREAM, dxl_id])
