//! The omni-wheel base: DJI C620 and CANopen CiA 402 motor controllers, kinematics, odometry, safety.
