//! CiA 402 drive profile: state machine, controlword/statusword, touch probe.
