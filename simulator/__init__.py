"""PyBullet simulation of N aerial manipulators and the flight-controller emulation.

- `simulator.actuators`: the rotors' thrust lag and the joints' torque limits (no pybullet;
  the allocation is `amcore.allocation`).
- `simulator.scene`: the bodies (ground, table, object, AMs) of a PyBullet client.
- `simulator.world`: `World`, the stepping physics of one scenario, with sensors and
  ground truth.

The control law never imports this package.
"""
