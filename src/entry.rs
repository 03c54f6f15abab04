//! The command's entry in a robot's library (what `--model-file` builds, see
//! [`crate::model_file`]): the C function `rbss_command` that runs a command line on the robot,
//! written by [`crate::export_command!`]. Above [`crate::cli`], which it calls; the loader in
//! `model_file` only names the symbols.

use std::ffi::{c_char, c_int};

/// The arguments of `rbss_command` as strings.
///
/// # Safety
/// `argv` points to `argc` NUL-terminated strings.
pub unsafe fn args(argc: c_int, argv: *const *const c_char) -> Vec<String> {
    (0..usize::try_from(argc).unwrap_or(0))
        .map(|i| {
            // SAFETY: the caller's contract.
            unsafe { std::ffi::CStr::from_ptr(*argv.add(i)) }
                .to_string_lossy()
                .into_owned()
        })
        .collect()
}

/// The command's entry in a robot's library (with `rbss_ffi::export!`, what `--model-file`
/// builds): `rbss_command(argc, argv)` runs the command line on the robot `$krate::$ty` and
/// returns the exit status; `rbss_cache_key()` is `$key`, the cache entry's. With
/// `without_derivatives`, for a robot generated without its derivative kernel
/// ([`crate::cli::main_without_derivatives`]: the subcommands that need it are errors).
#[macro_export]
macro_rules! export_command {
    ($krate:ident :: $ty:ident, $key:expr) => {
        $crate::export_command!(@ $krate :: $ty, $key, main_with_model);
    };
    ($krate:ident :: $ty:ident, $key:expr, without_derivatives) => {
        $crate::export_command!(@ $krate :: $ty, $key, main_without_derivatives);
    };
    (@ $krate:ident :: $ty:ident, $key:expr, $main:ident) => {
        /// # Safety
        /// `argv` holds `argc` NUL-terminated strings.
        #[unsafe(no_mangle)]
        pub unsafe extern "C" fn rbss_command(
            argc: ::std::ffi::c_int,
            argv: *const *const ::std::ffi::c_char,
        ) -> ::std::ffi::c_int {
            let args = unsafe { $crate::entry::args(argc, argv) };
            ::std::panic::catch_unwind(|| {
                let model = ::rbss_runtime::Model::new(
                    <$krate::$ty as ::core::default::Default>::default(),
                );
                ::std::ffi::c_int::from($crate::cli::$main(&args, model))
            })
            .unwrap_or(101)
        }
        #[unsafe(no_mangle)]
        pub extern "C" fn rbss_cache_key() -> *const ::std::ffi::c_char {
            concat!($key, "\0").as_ptr().cast()
        }
    };
}
