"""The simulator's MAVLink edge: the HIL lockstep frame out, actuator controls in."""
