//! Mock devices.
