//! The Machine conformance suite on the Modbus backend over Modbus RTU: `ModbusMachine`
//! and the simulated PLC on the two ends of a `socat` pseudo-terminal pair. Skipped
//! (with a line saying why) only where socat is missing; `scripts/test` installs it
//! first (`scripts/install-test-peers`).

probebridge_tests::machine_conformance!(probebridge_tests::conformance_modbus::ModbusRtu);
