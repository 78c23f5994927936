"""gyro_ctl: control laws for the gyroscope rotor, as pure functions of the state."""
