"""The free-running simulator's PX4 side: what one vehicle's PX4 does on its onboard MAVLink port.

- `commander`: the commander's state machine (arming, nav state, land detector, offboard
  liveness and failover), pure, driven by a time argument;
- `setpoint`: SET_ATTITUDE_TARGET read as PX4's mavlink receiver reads it, and what the
  emulated autopilot reports (pure);
- `port`: the MAVLink adapter of one vehicle (a UDP socket, PX4's streams and commands).

Source followed throughout: PX4-Autopilot v1.14.3 (tag v1.14.3, commit 1dacb4cd); file and line
references are to that tag.
"""
