//! [`export!`](crate::export): the `extern "C"` functions of `include/rbss.h` for one robot,
//! made from the ABI's table (`rbss_abi::functions!`).

/// The `extern "C"` functions of `include/rbss.h` for one robot type, in a `cdylib` crate:
/// `rbss_ffi::export!(stewart_6ups::Stewart6Ups, dynamics);` (or `kinematics` for a robot
/// generated without dynamics, whose dynamics functions return `RBSS_ERR_NO_DYNAMICS`; or
/// `version` for `rbss_abi_version` alone). The
/// crate `$krate` is the generated crate (its `N` and `M` are the sizes).
///
/// One function per entry of the table (`ffi/abi`, [`rbss_abi::functions!`]), calling the
/// function of this crate the entry names: the signatures are the table's.
#[macro_export]
macro_rules! export {
    ($krate:ident :: $ty:ident, dynamics) => {
        $crate::export!(@items $krate :: $ty, true);
        $crate::abi::functions!([$crate::export] @functions dynamics);
    };
    ($krate:ident :: $ty:ident, kinematics) => {
        $crate::export!(@items $krate :: $ty, false);
        $crate::abi::functions!([$crate::export] @functions kinematics);
    };
    // Only `rbss_abi_version` (the library `rbss --model-file` builds for the subcommands that
    // take no derivatives: the command's entry, `rbss::export_command!`, is all it offers).
    ($krate:ident :: $ty:ident, version) => {
        #[unsafe(no_mangle)]
        pub extern "C" fn rbss_abi_version() -> u32 {
            $crate::abi_version()
        }
    };
    (@items $krate:ident :: $ty:ident, $dynamics:expr) => {
        /// The robot's handle type.
        pub type RbssRobot = $crate::Handle<$krate::$ty, { $krate::N }, { $krate::M }>;
        /// The robot's kernels (`rbss_new`'s).
        type RbssKernels = $krate::$ty;
        /// Whether the dynamics functions work (`rbss_size(h, RBSS_DYNAMICS)`).
        const RBSS_HAS_DYNAMICS: bool = $dynamics;
    };
    // The table: one function per entry (the arrays' lengths are the table's and rbss.h's).
    (@functions $mode:ident $(
        $group:ident fn $name:ident ( $($arg:ident : $kind:ident $([$($len:tt)*])?),* ) -> $ret:ident
            = $($path:ident)::+ ( $($call:tt)* );
    )*) => {
        $($crate::export!(@function $mode $group $name ($($arg : $kind),*) -> $ret
            = [$($path)::+] ($($call)*));)*
    };
    // Without a handle: safe.
    (@function $mode:ident abi $name:ident () -> $ret:ident = [$($path:ident)::+] ($($call:tt)*)) => {
        #[unsafe(no_mangle)]
        pub extern "C" fn $name() -> $crate::export!(@type $ret) {
            $crate::$($path)::+($($call)*)
        }
    };
    // A dynamics function of a robot without dynamics: the error.
    (@function kinematics dynamics $name:ident ($h:ident : $hkind:ident $(, $arg:ident : $kind:ident)*)
        -> $ret:ident = [$($path:ident)::+] ($($call:tt)*)) => {
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        #[allow(clippy::too_many_arguments, unused_variables)]
        pub unsafe extern "C" fn $name(
            $h: $crate::export!(@type $hkind) $(, $arg: $crate::export!(@type $kind))*
        ) -> $crate::export!(@type $ret) {
            unsafe { $crate::kinematics::no_dynamics($h) }
        }
    };
    (@function $mode:ident $group:ident $name:ident ($($arg:ident : $kind:ident),*)
        -> $ret:ident = [$($path:ident)::+] ($($call:tt)*)) => {
        /// # Safety
        /// See `rbss.h`.
        #[unsafe(no_mangle)]
        #[allow(clippy::too_many_arguments)]
        pub unsafe extern "C" fn $name($($arg: $crate::export!(@type $kind)),*)
            -> $crate::export!(@type $ret) {
            unsafe { $crate::$($path)::+($($call)*) }
        }
    };
    // The kinds' Rust types.
    (@type handle) => { *mut RbssRobot };
    (@type handle_const) => { *const RbssRobot };
    (@type input) => { *const f64 };
    (@type input_or_null) => { *const f64 };
    (@type output) => { *mut f64 };
    (@type int) => { ::std::ffi::c_int };
    (@type size) => { usize };
    (@type double) => { f64 };
    (@type u32) => { u32 };
    (@type string) => { *const ::std::ffi::c_char };
    (@type void) => { () };
}
