//! A model file's robot as its loadable library (`rbss library --model-file`), called through
//! the C ABI of ffi/include/rbss.h: the runtime's solvers at any state, for tests whose robot
//! is not one of the generated crates.

use std::ffi::{CStr, c_char, c_int, c_void};
use std::path::{Path, PathBuf};
use std::process::Command;

type Handle = *mut c_void;

/// Builds (or finds in `cache`) the library of `model` with the `rbss` command under test.
pub fn library(model: &Path, cache: &Path) -> PathBuf {
    let exe = Path::new(env!("CARGO_BIN_EXE_rbss"));
    let target = exe.parent().and_then(Path::parent).unwrap();
    let out = Command::new(exe)
        .args(["library", "--model-file", model.to_str().unwrap()])
        .env("RBSS_CACHE", cache)
        .env("RBSS_CACHE_TARGET", target)
        .env_remove("RBSS_CODEGEN")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "rbss library: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    PathBuf::from(String::from_utf8(out.stdout).unwrap().trim())
}

/// A handle on a robot's library.
pub struct RobotLib {
    lib: libloading::Library,
    h: Handle,
    /// Coordinates, constraints, actuated coordinates, outputs.
    pub n: usize,
    pub m: usize,
    pub k: usize,
    pub p: usize,
}

impl Drop for RobotLib {
    fn drop(&mut self) {
        // SAFETY: the handle came from this library's rbss_new and is freed once.
        unsafe {
            if let Ok(f) = self.lib.get::<unsafe extern "C" fn(Handle)>(b"rbss_free") {
                f(self.h);
            }
        }
    }
}

impl RobotLib {
    pub fn open(path: &Path) -> Self {
        // SAFETY: an rbss robot library (checked by its ABI version below).
        unsafe {
            let lib = libloading::Library::new(path).unwrap();
            let version = lib
                .get::<unsafe extern "C" fn() -> u32>(b"rbss_abi_version")
                .unwrap()();
            assert_eq!(version, rbss_ffi::ABI_VERSION, "C ABI version");
            let h = lib
                .get::<unsafe extern "C" fn() -> Handle>(b"rbss_new")
                .unwrap()();
            assert!(!h.is_null(), "rbss_new failed");
            let size = *lib
                .get::<unsafe extern "C" fn(Handle, c_int) -> usize>(b"rbss_size")
                .unwrap();
            let (n, m, k, p) = (size(h, 0), size(h, 1), size(h, 2), size(h, 3));
            Self { lib, h, n, m, k, p }
        }
    }

    fn error(&self) -> String {
        // SAFETY: rbss_last_error returns a NUL-terminated string valid until the next call.
        unsafe {
            let f = self
                .lib
                .get::<unsafe extern "C" fn(Handle) -> *const c_char>(b"rbss_last_error")
                .unwrap();
            CStr::from_ptr(f(self.h)).to_string_lossy().into_owned()
        }
    }

    fn check(&self, what: &str, rc: c_int) -> Result<(), String> {
        if rc == 0 {
            Ok(())
        } else {
            Err(format!("{what}: code {rc}: {}", self.error()))
        }
    }

    /// Index in `X` of actuated coordinate `i` / of output `i`; a coordinate's name.
    pub fn actuated(&self, i: usize) -> usize {
        // SAFETY: i < k is the caller's; the function reads nothing else.
        unsafe {
            self.lib
                .get::<unsafe extern "C" fn(Handle, usize) -> usize>(b"rbss_actuated")
                .unwrap()(self.h, i)
        }
    }
    pub fn output(&self, i: usize) -> usize {
        // SAFETY: as `actuated`.
        unsafe {
            self.lib
                .get::<unsafe extern "C" fn(Handle, usize) -> usize>(b"rbss_output")
                .unwrap()(self.h, i)
        }
    }

    /// `rbss_ik` / `rbss_fk`: every coordinate from the outputs / the actuated ones, Newton
    /// from `start` (the home when `None`).
    pub fn ik(&self, pose: &[f64], start: Option<&[f64]>) -> Result<Vec<f64>, String> {
        self.position(b"rbss_ik", "rbss_ik", pose, self.p, start)
    }
    pub fn fk(&self, q: &[f64], start: Option<&[f64]>) -> Result<Vec<f64>, String> {
        self.position(b"rbss_fk", "rbss_fk", q, self.k, start)
    }
    fn position(
        &self,
        sym: &[u8],
        what: &str,
        given: &[f64],
        len: usize,
        start: Option<&[f64]>,
    ) -> Result<Vec<f64>, String> {
        assert_eq!(given.len(), len);
        let mut x = vec![0.0; self.n];
        // SAFETY: the arrays have the lengths of the header's comments.
        let rc = unsafe {
            let f = self
                .lib
                .get::<unsafe extern "C" fn(Handle, *const f64, *const f64, *mut f64) -> c_int>(sym)
                .unwrap();
            f(
                self.h,
                given.as_ptr(),
                start.map_or(std::ptr::null(), |s| s.as_ptr()),
                x.as_mut_ptr(),
            )
        };
        self.check(what, rc).map(|()| x)
    }

    /// `rbss_inverse_velocity` / `rbss_forward_velocity`: every rate at `x` from the outputs'
    /// / the actuated coordinates' rates.
    pub fn inverse_velocity(&self, x: &[f64], rates: &[f64]) -> Result<Vec<f64>, String> {
        assert_eq!(rates.len(), self.p);
        self.rates(b"rbss_inverse_velocity", "rbss_inverse_velocity", x, rates)
    }
    pub fn forward_velocity(&self, x: &[f64], rates: &[f64]) -> Result<Vec<f64>, String> {
        assert_eq!(rates.len(), self.k);
        self.rates(b"rbss_forward_velocity", "rbss_forward_velocity", x, rates)
    }
    fn rates(&self, sym: &[u8], what: &str, x: &[f64], rates: &[f64]) -> Result<Vec<f64>, String> {
        assert_eq!(x.len(), self.n);
        let mut out = vec![0.0; self.n];
        // SAFETY: as `position`.
        let rc = unsafe {
            let f = self
                .lib
                .get::<unsafe extern "C" fn(Handle, *const f64, *const f64, *mut f64) -> c_int>(sym)
                .unwrap();
            f(self.h, x.as_ptr(), rates.as_ptr(), out.as_mut_ptr())
        };
        self.check(what, rc).map(|()| out)
    }

    /// `rbss_inverse_acceleration` / `rbss_forward_acceleration`: every acceleration at
    /// `x`, `xdot` from the outputs' / the actuated coordinates' accelerations.
    pub fn inverse_acceleration(
        &self,
        x: &[f64],
        xdot: &[f64],
        acc: &[f64],
    ) -> Result<Vec<f64>, String> {
        assert_eq!(acc.len(), self.p);
        self.accelerations(
            b"rbss_inverse_acceleration",
            "rbss_inverse_acceleration",
            x,
            xdot,
            acc,
        )
    }
    pub fn forward_acceleration(
        &self,
        x: &[f64],
        xdot: &[f64],
        acc: &[f64],
    ) -> Result<Vec<f64>, String> {
        assert_eq!(acc.len(), self.k);
        self.accelerations(
            b"rbss_forward_acceleration",
            "rbss_forward_acceleration",
            x,
            xdot,
            acc,
        )
    }
    fn accelerations(
        &self,
        sym: &[u8],
        what: &str,
        x: &[f64],
        xdot: &[f64],
        acc: &[f64],
    ) -> Result<Vec<f64>, String> {
        assert_eq!((x.len(), xdot.len()), (self.n, self.n));
        let mut out = vec![0.0; self.n];
        type F =
            unsafe extern "C" fn(Handle, *const f64, *const f64, *const f64, *mut f64) -> c_int;
        // SAFETY: as `position`.
        let rc = unsafe {
            let f = self.lib.get::<F>(sym).unwrap();
            f(
                self.h,
                x.as_ptr(),
                xdot.as_ptr(),
                acc.as_ptr(),
                out.as_mut_ptr(),
            )
        };
        self.check(what, rc).map(|()| out)
    }

    /// `rbss_inverse_dynamics`: `(U, lambda)` for the motion `x, xdot, xddot`.
    pub fn inverse_dynamics(
        &self,
        x: &[f64],
        xdot: &[f64],
        xddot: &[f64],
    ) -> Result<(Vec<f64>, Vec<f64>), String> {
        assert_eq!((x.len(), xdot.len(), xddot.len()), (self.n, self.n, self.n));
        let (mut u, mut lambda) = (vec![0.0; self.k], vec![0.0; self.m]);
        type F = unsafe extern "C" fn(
            Handle,
            *const f64,
            *const f64,
            *const f64,
            *mut f64,
            *mut f64,
        ) -> c_int;
        // SAFETY: as `position`.
        let rc = unsafe {
            let f = self.lib.get::<F>(b"rbss_inverse_dynamics").unwrap();
            f(
                self.h,
                x.as_ptr(),
                xdot.as_ptr(),
                xddot.as_ptr(),
                u.as_mut_ptr(),
                lambda.as_mut_ptr(),
            )
        };
        self.check("rbss_inverse_dynamics", rc)
            .map(|()| (u, lambda))
    }

    /// `rbss_forward_dynamics`: `(Xddot, lambda)` under the forces `u`.
    pub fn forward_dynamics(
        &self,
        x: &[f64],
        xdot: &[f64],
        u: &[f64],
    ) -> Result<(Vec<f64>, Vec<f64>), String> {
        assert_eq!((x.len(), xdot.len(), u.len()), (self.n, self.n, self.k));
        let (mut xddot, mut lambda) = (vec![0.0; self.n], vec![0.0; self.m]);
        type F = unsafe extern "C" fn(
            Handle,
            *const f64,
            *const f64,
            *const f64,
            *mut f64,
            *mut f64,
        ) -> c_int;
        // SAFETY: as `position`.
        let rc = unsafe {
            let f = self.lib.get::<F>(b"rbss_forward_dynamics").unwrap();
            f(
                self.h,
                x.as_ptr(),
                xdot.as_ptr(),
                u.as_ptr(),
                xddot.as_mut_ptr(),
                lambda.as_mut_ptr(),
            )
        };
        self.check("rbss_forward_dynamics", rc)
            .map(|()| (xddot, lambda))
    }

    /// `rbss_energy`: `[T, Pi]`.
    pub fn energy(&self, x: &[f64], xdot: &[f64]) -> Result<[f64; 2], String> {
        assert_eq!((x.len(), xdot.len()), (self.n, self.n));
        let mut out = [0.0; 2];
        type F = unsafe extern "C" fn(Handle, *const f64, *const f64, *mut f64) -> c_int;
        // SAFETY: as `position`.
        let rc = unsafe {
            let f = self.lib.get::<F>(b"rbss_energy").unwrap();
            f(self.h, x.as_ptr(), xdot.as_ptr(), out.as_mut_ptr())
        };
        self.check("rbss_energy", rc).map(|()| out)
    }
}
