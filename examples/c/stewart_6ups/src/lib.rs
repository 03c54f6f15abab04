//! The 6-UPS (generated/stewart_6ups) behind the C ABI of `ffi/include/rbss.h`.
rbss_ffi::export!(stewart_6ups::Stewart6Ups, dynamics);
