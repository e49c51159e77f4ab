"""Pure core of the aerial-manipulation stack: parameters, model, control law.

Nothing in this package performs I/O beyond reading configuration files; it imports
numpy, pinocchio and the standard library only, so the control law can be used (and
tested) without pymavlink, zenoh or pybullet installed.

The method is Jeong & Kim, "Passivity-based Decentralized Control for Collaborative
Grasping of Under-Actuated Aerial Manipulators", ICRA 2023. Equation names in the
docstrings (eq. new_coord, eq. Com_controller, ...) are the labels of that paper.
`amcore.baseline` is the conventional controller it is compared with (Lee et al.'s geometric
tracking of the base, joint-space PD on the arm), behind the same step interface.
"""
