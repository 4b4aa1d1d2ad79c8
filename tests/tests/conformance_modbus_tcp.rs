//! The Machine conformance suite on the Modbus backend: `ModbusMachine` against the
//! simulated PLC over Modbus TCP on loopback.

probebridge_tests::machine_conformance!(probebridge_tests::conformance_modbus::ModbusTcp);
