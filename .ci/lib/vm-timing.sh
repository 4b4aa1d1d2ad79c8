# The CANopen timing both VM steps give the simulated machines (sourced by .ci/vcan/run
# and, inside the systemd VM, by tests/systemd/in-vm.sh). The VMs emulate their CPUs
# (TCG) on a 2-core machine: a 2 ms SYNC with a 150 ms heartbeat timeout cannot be held
# there. The results do not depend on these values: the latch is exact within the cycle.
#
# SYNC period, 10 ms.
VM_SYNC_US=${PROBEBRIDGE_VM_SYNC_US:-10000}
# The master's heartbeat timeout for the drives. It also sets the master's enable and
# settle timeouts (3 times it) and its probe arming timeout (twice it; once it ran out
# when it was once the heartbeat timeout: at 2 s mid-451 in the vcan VM, at 4 s in the
# systemd VM of CI 66). In the systemd VM a drive's heartbeat was 2010 ms late on the
# first move after the package's upgrade (CI of ce23731).
VM_HEARTBEAT_TIMEOUT_MS=${PROBEBRIDGE_VM_HEARTBEAT_TIMEOUT_MS:-4000}
# The master's own heartbeat period; the drives consume it with 3 times this period
# (6 s; a 3 s consumer time once ran out in a loaded CI host's VM).
VM_MASTER_HEARTBEAT_MS=${PROBEBRIDGE_VM_MASTER_HEARTBEAT_MS:-2000}
