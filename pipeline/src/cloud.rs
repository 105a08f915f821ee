//! Point clouds (being written).
