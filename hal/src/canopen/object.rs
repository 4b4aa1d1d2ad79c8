//! Object dictionary indices this project reads, writes or maps (CiA 301 communication
//! area, CiA 402 drive profile area).

// CiA 301 communication profile area.
pub const DEVICE_TYPE: u16 = 0x1000;
pub const ERROR_REGISTER: u16 = 0x1001;
pub const COB_ID_SYNC: u16 = 0x1005;
pub const COMMUNICATION_CYCLE_PERIOD: u16 = 0x1006;
pub const MANUFACTURER_DEVICE_NAME: u16 = 0x1008;
pub const COB_ID_EMCY: u16 = 0x1014;
pub const CONSUMER_HEARTBEAT_TIME: u16 = 0x1016;
pub const PRODUCER_HEARTBEAT_TIME: u16 = 0x1017;
pub const IDENTITY: u16 = 0x1018;
pub const SYNC_COUNTER_OVERFLOW: u16 = 0x1019;
/// RPDO communication parameter, RPDO1..4 at 0x1400..=0x1403.
pub const RPDO_COMMUNICATION: u16 = 0x1400;
/// RPDO mapping parameter, RPDO1..4 at 0x1600..=0x1603.
pub const RPDO_MAPPING: u16 = 0x1600;
/// TPDO communication parameter, TPDO1..4 at 0x1800..=0x1803.
pub const TPDO_COMMUNICATION: u16 = 0x1800;
/// TPDO mapping parameter, TPDO1..4 at 0x1A00..=0x1A03.
pub const TPDO_MAPPING: u16 = 0x1A00;

/// Sub-indices of the PDO communication parameter record.
pub mod pdo_comm_sub {
    pub const COB_ID: u8 = 1;
    pub const TRANSMISSION_TYPE: u8 = 2;
    pub const INHIBIT_TIME: u8 = 3;
    pub const EVENT_TIMER: u8 = 5;
}

// CiA 402 drive profile area.
/// CiA 402 abort connection option code: what the drive does when its connection to
/// the master is lost (heartbeat consumer expired).
pub const ABORT_CONNECTION_OPTION_CODE: u16 = 0x6007;
pub const ERROR_CODE: u16 = 0x603F;
pub const CONTROLWORD: u16 = 0x6040;
pub const STATUSWORD: u16 = 0x6041;
pub const QUICK_STOP_OPTION_CODE: u16 = 0x605A;
pub const MODES_OF_OPERATION: u16 = 0x6060;
pub const MODES_OF_OPERATION_DISPLAY: u16 = 0x6061;
pub const POSITION_DEMAND_VALUE: u16 = 0x6062;
pub const POSITION_ACTUAL_VALUE: u16 = 0x6064;
pub const FOLLOWING_ERROR_WINDOW: u16 = 0x6065;
pub const TARGET_POSITION: u16 = 0x607A;
/// Profile position: the velocity (increments/s) and the acceleration and deceleration
/// (increments/s²) of a move to a new set-point.
pub const PROFILE_VELOCITY: u16 = 0x6081;
pub const PROFILE_ACCELERATION: u16 = 0x6083;
pub const PROFILE_DECELERATION: u16 = 0x6084;
pub const TOUCH_PROBE_FUNCTION: u16 = 0x60B8;
pub const TOUCH_PROBE_STATUS: u16 = 0x60B9;
pub const TOUCH_PROBE_1_POSITIVE_EDGE: u16 = 0x60BA;
pub const TOUCH_PROBE_1_NEGATIVE_EDGE: u16 = 0x60BB;
pub const TOUCH_PROBE_2_POSITIVE_EDGE: u16 = 0x60BC;
pub const TOUCH_PROBE_2_NEGATIVE_EDGE: u16 = 0x60BD;
pub const TOUCH_PROBE_SOURCE: u16 = 0x60D0;
pub const FOLLOWING_ERROR_ACTUAL_VALUE: u16 = 0x60F4;
pub const SUPPORTED_DRIVE_MODES: u16 = 0x6502;
