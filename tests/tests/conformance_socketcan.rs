//! The Machine conformance suite on the CANopen backend over real SocketCAN: master and
//! simulated drives on two sockets of the interface named by `PROBEBRIDGE_TEST_CAN`
//! (`vcan0` inside the CI VM, see `.ci/vcan/run`). Without that variable every test
//! passes with a "SKIPPED" line: this host's kernel has no AF_CAN.
//!
//! In the VM: `PROBEBRIDGE_TEST_CAN=vcan0 conformance_socketcan-<hash> --test-threads=1`.

probebridge_tests::machine_conformance!(probebridge_tests::conformance::SocketCan);
