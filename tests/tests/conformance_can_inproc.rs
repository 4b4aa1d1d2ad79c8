//! The Machine conformance suite on the CANopen backend with simulated CiA 402 drives
//! on the in-process bus.

probebridge_tests::machine_conformance!(probebridge_tests::conformance::CanInproc);
