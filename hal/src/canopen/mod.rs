//! CANopen (CiA 301) protocol core: frames in, frames out, no I/O.
