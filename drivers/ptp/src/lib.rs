//! PTP v2 (IEEE 1588-2008): messages, a grandmaster and a measure-only slave with kernel timestamps.
