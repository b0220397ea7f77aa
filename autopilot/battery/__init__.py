"""The flight battery as the autopilot knows it: PX4's battery library (:mod:`.estimator`)."""
