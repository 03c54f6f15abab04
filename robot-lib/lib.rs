//! A robot's library for `rbss --model-file` (see Cargo.toml): the robot `$RBSS_ROBOT_LIB`
//! includes behind the C ABI (`ffi/include/rbss.h`) and the command, or nothing.
include!(concat!(env!("OUT_DIR"), "/robot.rs"));
