//! rbss-ffi: a generated robot as a loadable library with a C ABI.
//!
//! The ABI (version [`ABI_VERSION`]) is the same for every robot: a handle made by
//! `rbss_new`, sizes and names queried from it, and one function per solver or kernel of the
//! runtime over `double` arrays whose lengths the sizes give. `include/rbss.h` documents it
//! (the C programs' view); this crate holds its one implementation, generic over the robot.
//! A robot's `cdylib` is one line:
//!
//! ```ignore
//! rbss_ffi::export!(stewart_6ups::Stewart6Ups, dynamics);   // or `kinematics` (no dynamics)
//! ```
//!
//! The functions, their arguments and lengths are those of the ABI's table (crate rbss-abi,
//! `ffi/abi/src/lib.rs`): `export!` makes one `extern "C"` function per entry, calling the
//! function of this crate the entry names; `tests/abi.rs` checks `rbss.h` against the table.
//!
//! Errors are codes ([`RBSS_OK`] and the `RBSS_ERR_*` constants) plus a message kept in the
//! handle (`rbss_last_error`), valid until the next call on that handle. No function unwinds
//! into C: a panic (a bug) is caught and becomes [`RBSS_ERR_PANIC`].

use std::ffi::{CString, c_char, c_int};
use std::panic::{AssertUnwindSafe, catch_unwind};

use rbss_runtime::tasks::Robot;
use rbss_runtime::{
    Baumgarte, Data, Dynamics, IntegrateOptions, Kernels, Method, Model, Simulator, Stabilization,
};

/// The table of the C ABI (every `rbss_*` function, its arguments and lengths, the constants),
/// from which [`export!`] is made.
#[doc(hidden)]
pub use rbss_abi as abi;
pub use rbss_abi::{
    ABI_VERSION, RBSS_ERR_ARGUMENT, RBSS_ERR_NO_DYNAMICS, RBSS_ERR_NONFINITE, RBSS_ERR_PANIC,
    RBSS_ERR_SOLVER, RBSS_ERR_STATE, RBSS_METHOD_DOP853, RBSS_METHOD_DOPRI5, RBSS_OK,
};

/// `rbss_abi_version()`: [`ABI_VERSION`].
pub fn abi_version() -> u32 {
    ABI_VERSION
}

/// A robot behind the C ABI: its model, the solvers' data and the last error message.
pub struct Handle<K, const N: usize, const M: usize> {
    model: Model<K, N, M>,
    data: Data<N, M>,
    error: CString,
    names: Names,
    /// The derivative functions' buffers, made by the first of them (`derivatives.rs`).
    derivatives: Option<Box<derivatives::Workspace<N, M>>>,
}

/// The structure's names as C strings (made once).
struct Names {
    name: CString,
    coordinates: Vec<CString>,
    constraints: Vec<CString>,
}

/// An error: its code and message.
type Failure = (c_int, String);

fn c_string(s: &str) -> CString {
    CString::new(s.replace('\0', " ")).unwrap_or_default()
}

thread_local! {
    /// The message of the last `rbss_new` that failed on this thread.
    static NEW_ERROR: std::cell::RefCell<CString> = std::cell::RefCell::new(CString::default());
}

/// `rbss_new`: a handle at the robot's home, or null (the message in `rbss_last_error(NULL)`).
pub fn new<K: Robot<N, M>, const N: usize, const M: usize>(kernels: K) -> *mut Handle<K, N, M> {
    let made = catch_unwind(AssertUnwindSafe(|| {
        Model::try_new(kernels).map(|model| {
            let data = Data::new(&model);
            let s = model.structure();
            let names = Names {
                name: c_string(s.name),
                coordinates: s.coordinates.iter().map(|c| c_string(c)).collect(),
                constraints: s.constraints.iter().map(|c| c_string(c)).collect(),
            };
            Box::new(Handle {
                model,
                data,
                error: CString::default(),
                names,
                derivatives: None,
            })
        })
    }));
    let message = match made {
        Ok(Ok(h)) => return Box::into_raw(h),
        Ok(Err(e)) => e.to_string(),
        Err(_) => "rbss_new: a panic (a bug in rbss)".to_string(),
    };
    NEW_ERROR.with(|m| *m.borrow_mut() = c_string(&message));
    std::ptr::null_mut()
}

/// `rbss_free`.
///
/// # Safety
/// `h` is null or a handle from `rbss_new` of this library, not freed before.
pub unsafe fn free<K, const N: usize, const M: usize>(h: *mut Handle<K, N, M>) {
    if !h.is_null() {
        // SAFETY: the caller's contract.
        drop(unsafe { Box::from_raw(h) });
    }
}

/// `rbss_last_error`: the message of the last failed call on `h` ("" after a success), or of
/// the last failed `rbss_new` on this thread when `h` is null.
///
/// # Safety
/// `h` is null or a live handle.
pub unsafe fn last_error<K, const N: usize, const M: usize>(
    h: *const Handle<K, N, M>,
) -> *const c_char {
    // SAFETY: the caller's contract.
    match unsafe { h.as_ref() } {
        Some(h) => h.error.as_ptr(),
        None => NEW_ERROR.with(|m| m.borrow().as_ptr()),
    }
}

/// `rbss_size(h, what)`: a size of the robot (`what`: `RBSS_COORDINATES` ... `RBSS_DYNAMICS`
/// of [`abi`]), or `usize::MAX` for a null handle or an unknown `what`.
///
/// # Safety
/// `h` is null or a live handle.
pub unsafe fn size<K: Robot<N, M>, const N: usize, const M: usize>(
    h: *const Handle<K, N, M>,
    what: c_int,
    dynamics: bool,
) -> usize {
    // SAFETY: the caller's contract.
    let Some(h) = (unsafe { h.as_ref() }) else {
        return usize::MAX;
    };
    let s = h.model.structure();
    match what {
        rbss_abi::RBSS_COORDINATES => N,
        rbss_abi::RBSS_CONSTRAINTS => M,
        rbss_abi::RBSS_ACTUATED => s.actuated.len(),
        rbss_abi::RBSS_OUTPUTS => s.outputs.len(),
        rbss_abi::RBSS_DYNAMICS => usize::from(dynamics),
        _ => usize::MAX,
    }
}

/// `rbss_name(h)`: the robot's name (null for a null handle).
///
/// # Safety
/// `h` is null or a live handle; the string lives as long as the handle.
pub unsafe fn name<K, const N: usize, const M: usize>(h: *const Handle<K, N, M>) -> *const c_char {
    // SAFETY: the caller's contract.
    unsafe { h.as_ref() }.map_or(std::ptr::null(), |h| h.names.name.as_ptr())
}

/// `rbss_coordinate(h, i)` / `rbss_constraint(h, i)`: the name of coordinate (constraint) `i`,
/// null out of range.
///
/// # Safety
/// `h` is null or a live handle; the string lives as long as the handle.
pub unsafe fn label<K, const N: usize, const M: usize>(
    h: *const Handle<K, N, M>,
    constraint: bool,
    i: usize,
) -> *const c_char {
    // SAFETY: the caller's contract.
    let Some(h) = (unsafe { h.as_ref() }) else {
        return std::ptr::null();
    };
    let list = if constraint {
        &h.names.constraints
    } else {
        &h.names.coordinates
    };
    list.get(i).map_or(std::ptr::null(), |c| c.as_ptr())
}

/// `rbss_actuated(h, i)` / `rbss_output(h, i)`: the coordinate index of actuated (output)
/// coordinate `i`, or `usize::MAX` out of range.
///
/// # Safety
/// `h` is null or a live handle.
pub unsafe fn index<K: Robot<N, M>, const N: usize, const M: usize>(
    h: *const Handle<K, N, M>,
    output: bool,
    i: usize,
) -> usize {
    // SAFETY: the caller's contract.
    let Some(h) = (unsafe { h.as_ref() }) else {
        return usize::MAX;
    };
    let s = h.model.structure();
    let list = if output { s.outputs } else { s.actuated };
    list.get(i).copied().unwrap_or(usize::MAX)
}

/// Reads `len` doubles at `p` (null: `None`), every one finite.
///
/// # Safety
/// `p` is null or points to `len` doubles.
unsafe fn read(p: *const f64, len: usize, what: &str) -> Result<Vec<f64>, Failure> {
    if p.is_null() {
        return Err((RBSS_ERR_ARGUMENT, format!("`{what}` is a null pointer")));
    }
    // SAFETY: the caller's contract.
    let v = unsafe { std::slice::from_raw_parts(p, len) }.to_vec();
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err((
            RBSS_ERR_ARGUMENT,
            format!("`{what}`[{i}] is not finite ({})", v[i]),
        ));
    }
    Ok(v)
}

/// `N` finite doubles at `p`.
///
/// # Safety
/// `p` is null or points to `N` doubles.
unsafe fn read_n<const L: usize>(p: *const f64, what: &str) -> Result<[f64; L], Failure> {
    // SAFETY: the caller's contract.
    let v = unsafe { read(p, L, what) }?;
    let mut out = [0.0; L];
    out.copy_from_slice(&v);
    Ok(out)
}

/// `p + offset`, or null for a null `p` (then refused by [`read`]).
fn ptr(p: *const f64, offset: usize) -> *const f64 {
    if p.is_null() {
        p
    } else {
        p.wrapping_add(offset)
    }
}

/// `p + offset`, or null for a null `p` (then refused by [`write`]).
fn ptr_mut(p: *mut f64, offset: usize) -> *mut f64 {
    if p.is_null() {
        p
    } else {
        p.wrapping_add(offset)
    }
}

/// [`RBSS_ERR_ARGUMENT`] for the first null output: checked before anything is computed or
/// written, so that a function with several outputs writes none of them when one is null.
fn outputs_given(outputs: &[(*mut f64, &str)]) -> Result<(), Failure> {
    match outputs.iter().find(|(p, _)| p.is_null()) {
        Some((_, what)) => Err((RBSS_ERR_ARGUMENT, format!("`{what}` is a null pointer"))),
        None => Ok(()),
    }
}

/// Writes `v` to `p`.
///
/// # Safety
/// `p` is null or points to `v.len()` writable doubles.
unsafe fn write(p: *mut f64, v: &[f64], what: &str) -> Result<(), Failure> {
    if p.is_null() {
        return Err((RBSS_ERR_ARGUMENT, format!("`{what}` is a null pointer")));
    }
    // SAFETY: the caller's contract.
    unsafe { std::ptr::copy_nonoverlapping(v.as_ptr(), p, v.len()) };
    Ok(())
}

/// Writes a raw kernel's output `v` to `p`: [`RBSS_ERR_NONFINITE`] (nothing written) when an
/// entry is inf or NaN, naming the first and the largest input (what takes a formula out of its
/// range, e.g. `x = 1e300`).
///
/// # Safety
/// As [`write`].
unsafe fn write_finite(
    p: *mut f64,
    v: &[f64],
    what: &str,
    inputs: &[&[f64]],
) -> Result<(), Failure> {
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        let largest = inputs
            .iter()
            .flat_map(|a| a.iter())
            .fold(0.0_f64, |m, x| m.max(x.abs()));
        return Err((
            RBSS_ERR_NONFINITE,
            format!(
                "`{what}`[{i}] is not finite ({}): the input (largest |value| {largest:e}) is \
                 outside the range the model's formulas hold in",
                v[i]
            ),
        ));
    }
    // SAFETY: the caller's contract.
    unsafe { write(p, v, what) }
}

fn solver(e: impl std::fmt::Display) -> Failure {
    (RBSS_ERR_SOLVER, e.to_string())
}

/// Runs `f` on the handle: the code, the message stored (cleared on success), panics caught.
///
/// # Safety
/// `h` is null or a live handle not used by another thread during the call.
pub unsafe fn call<K, const N: usize, const M: usize>(
    h: *mut Handle<K, N, M>,
    f: impl FnOnce(&mut Handle<K, N, M>) -> Result<(), Failure>,
) -> c_int {
    // SAFETY: the caller's contract.
    let Some(h) = (unsafe { h.as_mut() }) else {
        return RBSS_ERR_ARGUMENT;
    };
    let (code, message) = match catch_unwind(AssertUnwindSafe(|| f(&mut *h))) {
        Ok(Ok(())) => (RBSS_OK, String::new()),
        Ok(Err((code, message))) => (code, message),
        Err(_) => (RBSS_ERR_PANIC, "a panic (a bug in rbss)".to_string()),
    };
    h.error = c_string(&message);
    code
}

impl<K: Robot<N, M>, const N: usize, const M: usize> Handle<K, N, M> {
    /// Sets `data.x` to the start `x0` (null: the home).
    ///
    /// # Safety
    /// `x0` is null or points to `N` doubles.
    unsafe fn start(&mut self, x0: *const f64) -> Result<(), Failure> {
        self.data.x = if x0.is_null() {
            let mut x = [0.0; N];
            x.copy_from_slice(self.model.structure().home);
            x
        } else {
            // SAFETY: the caller's contract.
            unsafe { read_n(x0, "x_start") }?
        };
        Ok(())
    }

    fn actuated(&self) -> usize {
        self.model.structure().actuated.len()
    }

    fn outputs(&self) -> usize {
        self.model.structure().outputs.len()
    }
}

pub mod derivatives;
pub mod dynamics;
mod export;
pub mod kinematics;
