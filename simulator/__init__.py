"""PyBullet simulation of N aerial manipulators and the flight-controller emulation.

- `simulator.mixer`: pure numpy thrust/torque allocation and limits (no pybullet).
- `simulator.scene`: the bodies (ground, table, object, AMs) of a PyBullet client.
- `simulator.world`: `World`, the stepping physics of one scenario, with sensors and
  ground truth.

The control law never imports this package.
"""
