//! `rbss._native`: the Python package's compiled core, one extension for every robot.
//!
//! `Robot(library_path)` loads a robot's library (the `--model-file` cache's cdylib, the one
//! the ctypes layer loads too) with libloading, checks its C ABI version and calls the ABI's
//! functions (`ffi/include/rbss.h`) through function pointers: numpy arrays in and out, batched
//! `(k, n)` inputs looped here, errors raised as `rbss.RbssError` with the library's message.
//! The methods check what the ctypes layer checks, with the same messages.

use std::ffi::{CStr, c_char, c_int, c_void};

use libloading::Library;
use numpy::{IxDyn, PyArrayDyn, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{IntoPyDict, PyDict, PyTuple, PyType};

use rbss_abi::{
    ABI_VERSION, RBSS_ACTUATED, RBSS_CONSTRAINTS, RBSS_COORDINATES, RBSS_DYNAMICS,
    RBSS_LINEARIZE_ACTUATED, RBSS_LINEARIZE_OUTPUTS, RBSS_METHOD_DOP853, RBSS_METHOD_DOPRI5,
    RBSS_OUTPUTS, RBSS_STEP_RK4, RBSS_STEP_SEMI_IMPLICIT_EULER,
};

type H = *mut c_void;
type In = *const f64;
type Out = *mut f64;
/// `f(h, a, out)`: constraints, jacobian, mass_matrix (the helpers' types; every function's own
/// type is the table's, in `Api`).
type Fn1 = unsafe extern "C" fn(H, In, Out) -> c_int;
/// `f(h, a, b, out)`: ik, fk, the velocities, gamma, psi, energy.
type Fn2 = unsafe extern "C" fn(H, In, In, Out) -> c_int;
/// `f(h, a, b, c, out0, ..., out7)`: the derivatives of forward and inverse dynamics.
type Fn3x8 = unsafe extern "C" fn(H, In, In, In, Out, Out, Out, Out, Out, Out, Out, Out) -> c_int;

/// `Api`: one function pointer per function of the C ABI's table (rbss-abi), of the table's
/// type, looked up by name when a library is loaded.
macro_rules! api {
    ($(
        $group:ident fn $name:ident ( $($arg:ident : $kind:ident $([$($len:tt)*])?),* ) -> $ret:ident
            = $($path:ident)::+ ( $($call:tt)* );
    )*) => {
        /// The library's functions, looked up once: every one of the table (a library without
        /// one is refused), not every one called.
        #[allow(dead_code)]
        struct Api {
            $($name: unsafe extern "C" fn($(api!(@type $kind)),*) -> api!(@type $ret),)*
        }

        impl Api {
            fn load(lib: &Library, path: &str) -> PyResult<Self> {
                Ok(Self { $($name: sym(lib, path, stringify!($name))?,)* })
            }
        }
    };
    (@type handle) => { H };
    (@type handle_const) => { *const c_void };
    (@type input) => { In };
    (@type input_or_null) => { In };
    (@type output) => { Out };
    (@type int) => { c_int };
    (@type size) => { usize };
    (@type double) => { f64 };
    (@type u32) => { u32 };
    (@type string) => { *const c_char };
    (@type void) => { () };
}

rbss_abi::functions!([api]);

/// The handle. rbss.h asks for one caller at a time per handle (any thread): the GIL gives that.
/// Every call on it, and the read of its error message, runs with the GIL held and no Python
/// code in between (the core never releases the GIL), so two threads' calls cannot overlap. The
/// methods take `&Robot`, not `&mut Robot`: a method holds its borrow while it runs Python code
/// (numpy's conversions), during which another thread may call the same robot, and pyo3 would
/// refuse that thread an exclusive borrow ("Already borrowed").
struct Handle(H);
// SAFETY: the handle is heap memory of the library's, with no thread affinity; every use of it
// is under the GIL with no Python code between a call and its error read (see above).
unsafe impl Send for Handle {}
unsafe impl Sync for Handle {}

/// A robot's library, loaded: sizes and names as attributes, solvers as methods.
#[pyclass(subclass, module = "rbss._native")]
struct Robot {
    api: Api,
    h: Handle,
    /// The library file.
    #[pyo3(get)]
    library_path: String,
    #[pyo3(get)]
    name: String,
    #[pyo3(get)]
    n: usize,
    #[pyo3(get)]
    m: usize,
    #[pyo3(get)]
    actuated: usize,
    #[pyo3(get)]
    outputs: usize,
    #[pyo3(get)]
    has_dynamics: bool,
    #[pyo3(get)]
    coordinates: Vec<String>,
    #[pyo3(get)]
    constraint_names: Vec<String>,
    #[pyo3(get)]
    actuated_index: Vec<usize>,
    #[pyo3(get)]
    output_index: Vec<usize>,
    /// The home (one array, as the ctypes layer's attribute).
    #[pyo3(get)]
    home: Py<PyAny>,
    /// Last: dropped after `h` is freed (`Drop`).
    _lib: Library,
}

impl Drop for Robot {
    fn drop(&mut self) {
        // SAFETY: the handle came from this library's `rbss_new` and is freed once.
        unsafe { (self.api.rbss_free)(self.h.0) }
    }
}

/// `rbss.RbssError`, looked up when first raised (the package defines it; without the package,
/// a RuntimeError). The exception is made lazily, when the method has returned: its `__init__`
/// is Python code, during which another thread may run, and it must find the robot free (not
/// borrowed by this call: PyO3 would refuse that thread's call).
fn rbss_error(py: Python<'_>, code: c_int, message: String) -> PyErr {
    static CLASS: PyOnceLock<Py<PyType>> = PyOnceLock::new();
    let class = CLASS.get_or_try_init(py, || {
        py.import("rbss")
            .and_then(|m| m.getattr("RbssError"))
            .and_then(|c| Ok(c.cast_into::<PyType>()?.unbind()))
    });
    match class {
        Ok(c) => PyErr::from_type(c.bind(py).clone(), (code, message)),
        Err(_) => PyRuntimeError::new_err(message),
    }
}

fn c_str(p: *const c_char) -> String {
    if p.is_null() {
        return String::new();
    }
    // SAFETY: the library's strings are NUL-terminated and live while the handle does.
    unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
}

/// A symbol of the library, copied out (the library outlives every use: `Robot` owns it).
fn sym<T: Copy>(lib: &Library, path: &str, name: &str) -> PyResult<T> {
    // SAFETY: `T` is the function's type in rbss.h (ABI version checked before the others).
    unsafe { lib.get::<T>(name.as_bytes()) }
        .map(|s| *s)
        .map_err(|e| PyRuntimeError::new_err(format!("{path}: {e}")))
}

/// Whether numpy lets `a` be written (NPY_ARRAY_WRITEABLE).
fn writeable(a: &Bound<'_, PyArrayDyn<f64>>) -> bool {
    // SAFETY: `a` is a live numpy array; its flags field is numpy's documented ABI.
    unsafe { (*a.as_array_ptr()).flags & numpy::npyffi::NPY_ARRAY_WRITEABLE != 0 }
}

/// Python's repr of a shape: `(24,)`, `(3, 24)`.
fn shape_repr(shape: &[usize]) -> String {
    match shape {
        [a] => format!("({a},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// `v` as a C-contiguous float64 array (no copy when it is one: `np.ascontiguousarray`).
fn contiguous<'py>(v: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
    if let Ok(a) = v.cast::<PyArrayDyn<f64>>()
        && a.is_c_contiguous()
    {
        return Ok(a.clone());
    }
    static ASCONTIGUOUS: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
    let py = v.py();
    let f = ASCONTIGUOUS.get_or_try_init(py, || {
        py.import("numpy")
            .and_then(|m| m.getattr("ascontiguousarray"))
            .map(Bound::unbind)
    })?;
    let np_f64 = py.import("numpy")?.getattr("float64")?;
    let kwargs = [("dtype", np_f64)].into_py_dict(py)?;
    Ok(f.bind(py)
        .call((v,), Some(&kwargs))?
        .cast_into::<PyArrayDyn<f64>>()?)
}

/// An input: its array (kept alive while the call runs), its data and row length.
struct Arg<'py> {
    a: Bound<'py, PyArrayDyn<f64>>,
    data: In,
    len: usize,
}

/// The inputs and outputs of one call, checked: `k` rows (`batched`) or one.
struct Call<'py> {
    k: usize,
    batched: bool,
    ins: Vec<Arg<'py>>,
    /// Optional inputs given as one row for every row (`x_start`, `u` of simulate): null when
    /// absent, else the row.
    shared: Vec<In>,
    _shared_keep: Vec<Bound<'py, PyArrayDyn<f64>>>,
    /// The outputs: new arrays, or the `out` arrays, checked writable and sharing no memory
    /// with the inputs or each other. The library runs with the GIL held (no Python code runs
    /// meanwhile), so nothing else writes the inputs or reads the outputs during the call.
    /// (numpy's borrow checking would say the same at 90 ns per array: BENCHMARKS.md.)
    outs: Vec<(Bound<'py, PyArrayDyn<f64>>, Out, usize)>,
    /// The `out` argument as given (what the call returns).
    given: Option<Bound<'py, PyAny>>,
}

impl<'py> Call<'py> {
    /// Checks the inputs `(value, row length, name)` as the ctypes layer does, and makes (or
    /// checks, from `out`) the outputs of the given row lengths.
    fn new(
        py: Python<'py>,
        inputs: &[(&Bound<'py, PyAny>, usize, &str)],
        shared: &[(Option<&Bound<'py, PyAny>>, usize, &str)],
        out_lengths: &[usize],
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Self> {
        let mut ins = Vec::with_capacity(inputs.len());
        for &(v, len, what) in inputs {
            let a = contiguous(v)?;
            let shape = a.shape();
            if !(shape.len() == 1 || shape.len() == 2) || shape[shape.len() - 1] != len {
                return Err(PyValueError::new_err(format!(
                    "{what}: expected shape ({len},) or (k, {len}), got {}",
                    shape_repr(shape)
                )));
            }
            let data = a.data() as In;
            ins.push(Arg { a, data, len });
        }
        let batched = ins[0].a.ndim() == 2;
        let k = if batched { ins[0].a.shape()[0] } else { 1 };
        for a in &ins {
            if (a.a.ndim() == 2) != batched || (batched && a.a.shape()[0] != k) {
                return Err(PyValueError::new_err(
                    "batched inputs need the same number of rows",
                ));
            }
        }
        let mut shared_ptrs = Vec::with_capacity(shared.len());
        let mut shared_keep = Vec::new();
        for &(v, len, what) in shared {
            match v {
                Some(v) if !v.is_none() => {
                    let a = contiguous(v)?;
                    if a.shape() != [len] {
                        return Err(PyValueError::new_err(format!(
                            "{what}: expected shape ({len},), got {}",
                            shape_repr(a.shape())
                        )));
                    }
                    shared_ptrs.push(a.data() as In);
                    shared_keep.push(a);
                }
                _ => shared_ptrs.push(std::ptr::null()),
            }
        }
        let mut outs = Vec::with_capacity(out_lengths.len());
        match out {
            Some(o) if !o.is_none() => {
                let given: Vec<Bound<'py, PyAny>> = if out_lengths.len() == 1 {
                    vec![o.clone()]
                } else {
                    let t = o
                        .cast::<PyTuple>()
                        .ok()
                        .filter(|t| t.len() == out_lengths.len())
                        .ok_or_else(|| {
                            PyValueError::new_err(format!(
                                "out: expected a tuple of {} arrays",
                                out_lengths.len()
                            ))
                        })?;
                    t.iter().collect()
                };
                // The memory every input and output spans: an output may overlap none other.
                let span = |a: &Bound<'py, PyArrayDyn<f64>>| {
                    let p = a.data() as usize;
                    p..p + 8 * a.len()
                };
                let mut spans: Vec<_> = ins.iter().map(|a| span(&a.a)).collect();
                spans.extend(shared_keep.iter().map(span));
                for (g, &len) in given.iter().zip(out_lengths) {
                    let want: &[usize] = if batched { &[k, len] } else { &[len] };
                    let a = g
                        .cast::<PyArrayDyn<f64>>()
                        .ok()
                        .filter(|a| a.is_c_contiguous() && a.shape() == want && writeable(a))
                        .ok_or_else(|| {
                            PyValueError::new_err(format!(
                                "out: expected a writable C-contiguous float64 array of shape {}",
                                shape_repr(want)
                            ))
                        })?;
                    let s = span(a);
                    if spans.iter().any(|t| s.start < t.end && t.start < s.end) {
                        return Err(PyValueError::new_err(
                            "out: shares memory with an input or another output",
                        ));
                    }
                    spans.push(s);
                    outs.push((a.clone(), a.data(), len));
                }
            }
            _ => {
                for &len in out_lengths {
                    let dim = if batched {
                        IxDyn(&[k, len])
                    } else {
                        IxDyn(&[len])
                    };
                    // SAFETY: uninitialised f64s, written by the library before they are read
                    // (the array is returned only after a successful call).
                    let a = unsafe { PyArrayDyn::<f64>::new(py, dim, false) };
                    let data = a.data();
                    outs.push((a, data, len));
                }
            }
        }
        Ok(Self {
            k,
            batched,
            ins,
            shared: shared_ptrs,
            _shared_keep: shared_keep,
            outs,
            given: out.filter(|o| !o.is_none()).cloned(),
        })
    }

    fn input(&self, j: usize, row: usize) -> In {
        // SAFETY: row < k, and every input has k rows of `len` (checked in `new`).
        unsafe { self.ins[j].data.add(row * self.ins[j].len) }
    }

    fn output(&self, j: usize, row: usize) -> Out {
        // SAFETY: as `input`, for the outputs (made or checked with k rows of `len`).
        unsafe { self.outs[j].1.add(row * self.outs[j].2) }
    }

    /// The outputs: one array, or a tuple.
    fn result(self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let Self { outs, given, .. } = self;
        if let Some(given) = given {
            Ok(given)
        } else if outs.len() == 1 {
            Ok(outs
                .into_iter()
                .next()
                .map(|(a, ..)| a.into_any())
                .unwrap_or_else(|| py.None().into_bound(py)))
        } else {
            Ok(PyTuple::new(py, outs.into_iter().map(|(a, ..)| a))?.into_any())
        }
    }
}

impl Robot {
    fn check(&self, py: Python<'_>, code: c_int) -> PyResult<()> {
        if code == 0 {
            return Ok(());
        }
        // SAFETY: the handle is live; the message lives until the next call on it.
        let message = c_str(unsafe { (self.api.rbss_last_error)(self.h.0) });
        Err(rbss_error(py, code, message))
    }

    /// Runs `f` on every row of `call`, raising the first failure.
    fn rows<'py>(
        &self,
        py: Python<'py>,
        call: Call<'py>,
        mut f: impl FnMut(H, &Call<'py>, usize) -> c_int,
    ) -> PyResult<Bound<'py, PyAny>> {
        for row in 0..call.k {
            let code = f(self.h.0, &call, row);
            self.check(py, code)?;
        }
        call.result(py)
    }

    fn one<'py>(
        &self,
        py: Python<'py>,
        f: Fn1,
        a: (&Bound<'py, PyAny>, usize, &str),
        out_len: usize,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let call = Call::new(py, &[a], &[], &[out_len], out)?;
        // SAFETY: the pointers hold the lengths rbss.h asks (checked by `Call::new`).
        self.rows(py, call, |h, c, r| unsafe {
            f(h, c.input(0, r), c.output(0, r))
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn two<'py>(
        &self,
        py: Python<'py>,
        f: Fn2,
        a: (&Bound<'py, PyAny>, usize, &str),
        b: (&Bound<'py, PyAny>, usize, &str),
        out_len: usize,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let call = Call::new(py, &[a, b], &[], &[out_len], out)?;
        // SAFETY: as in `one`.
        self.rows(py, call, |h, c, r| unsafe {
            f(h, c.input(0, r), c.input(1, r), c.output(0, r))
        })
    }

    /// ik / fk: one input per row, `x_start` shared (null: the home).
    fn solve<'py>(
        &self,
        py: Python<'py>,
        f: Fn2,
        a: (&Bound<'py, PyAny>, usize, &str),
        x_start: Option<&Bound<'py, PyAny>>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let n = self.n;
        let call = Call::new(py, &[a], &[(x_start, n, "x_start")], &[n], out)?;
        // SAFETY: as in `one`; x_start is null or n values.
        self.rows(py, call, |h, c, r| unsafe {
            f(h, c.input(0, r), c.shared[0], c.output(0, r))
        })
    }

    /// `f(handle, row)` on every row of the derivative functions' inputs `ins` (x, xdot, u),
    /// the outputs of the `(rows, cols)` `shapes` made here; then each output shaped: a vector
    /// (`cols` None) as it is, a column-major matrix as numpy's `(..., rows, cols)` (a view).
    fn shaped_rows<'py>(
        &self,
        py: Python<'py>,
        ins: &[(&Bound<'py, PyAny>, usize, &str)],
        shapes: &[(usize, Option<usize>)],
        mut f: impl FnMut(H, &Call<'py>, usize) -> c_int,
    ) -> PyResult<Vec<Bound<'py, PyAny>>> {
        let lengths: Vec<usize> = shapes.iter().map(|&(r, c)| r * c.unwrap_or(1)).collect();
        let call = Call::new(py, ins, &[], &lengths, None)?;
        for row in 0..call.k {
            let code = f(self.h.0, &call, row);
            self.check(py, code)?;
        }
        let mut out = Vec::with_capacity(shapes.len());
        for ((a, ..), &(rows, cols)) in call.outs.into_iter().zip(shapes) {
            let a = a.into_any();
            out.push(match cols {
                None => a,
                Some(cols) => {
                    let mut to: Vec<usize> = if call.batched { vec![call.k] } else { vec![] };
                    to.extend([cols, rows]);
                    a.call_method1("reshape", (PyTuple::new(py, to)?,))?
                        .call_method1("swapaxes", (-1, -2))?
                }
            });
        }
        Ok(out)
    }

    /// One call of a derivative function (three inputs, eight outputs) per row: the outputs
    /// shaped by `shapes` (vectors, or column-major rows x cols matrices) in a dict under `keys`.
    fn derivative_dict<'py>(
        &self,
        py: Python<'py>,
        f: Fn3x8,
        ins: &[(&Bound<'py, PyAny>, usize, &str); 3],
        shapes: &[(usize, Option<usize>); 8],
        keys: [&str; 8],
    ) -> PyResult<Bound<'py, PyAny>> {
        // SAFETY: as in `one`: the outputs hold the lengths of rbss.h.
        let outs = self.shaped_rows(py, ins, shapes, |h, c, r| unsafe {
            f(
                h,
                c.input(0, r),
                c.input(1, r),
                c.input(2, r),
                c.output(0, r),
                c.output(1, r),
                c.output(2, r),
                c.output(3, r),
                c.output(4, r),
                c.output(5, r),
                c.output(6, r),
                c.output(7, r),
            )
        })?;
        let d = PyDict::new(py);
        for (k, v) in keys.into_iter().zip(outs) {
            d.set_item(k, v)?;
        }
        Ok(d.into_any())
    }

    /// A column-major (m x n) kernel per row as numpy's (m, n) (or (k, m, n)), a view.
    fn matrix<'py>(
        &self,
        py: Python<'py>,
        f: Fn1,
        x: &Bound<'py, PyAny>,
        rows: usize,
        cols: usize,
    ) -> PyResult<Bound<'py, PyAny>> {
        let n = self.n;
        let flat = self.one(py, f, (x, n, "x"), rows * cols, None)?;
        let shape = flat.getattr("shape")?.cast_into::<PyTuple>()?;
        let mut to: Vec<usize> = shape.iter().map(|d| d.extract()).collect::<PyResult<_>>()?;
        to.pop();
        to.extend([cols, rows]);
        flat.call_method1("reshape", (PyTuple::new(py, to)?,))?
            .call_method1("swapaxes", (-1, -2))
    }
}

#[pymethods]
impl Robot {
    #[new]
    fn new(py: Python<'_>, library_path: &Bound<'_, PyAny>) -> PyResult<Self> {
        // A str or an os.PathLike.
        let path = library_path
            .extract::<std::path::PathBuf>()?
            .to_string_lossy()
            .into_owned();
        // SAFETY: a library rbss built (its initialisers are Rust's: none that misbehave);
        // its ABI version is checked before any other function is used.
        let lib = unsafe { Library::new(&path) }
            .map_err(|e| rbss_error(py, -1, format!("{path}: {e}")))?;
        let version: unsafe extern "C" fn() -> u32 = sym(&lib, &path, "rbss_abi_version")?;
        // SAFETY: rbss_abi_version takes nothing and returns a u32 in every version.
        let v = unsafe { version() };
        if v != ABI_VERSION {
            return Err(rbss_error(
                py,
                -1,
                format!("{path}: C ABI {v}, expected {ABI_VERSION}"),
            ));
        }
        let api = Api::load(&lib, &path)?;
        // SAFETY: rbss.h's functions on a live handle, with the lengths it gives.
        unsafe {
            let h = (api.rbss_new)();
            if h.is_null() {
                let message = c_str((api.rbss_last_error)(std::ptr::null()));
                return Err(rbss_error(py, -1, message));
            }
            // The handle is freed by `Drop` from here on.
            let size = |what| (api.rbss_size)(h, what);
            let (n, m) = (size(RBSS_COORDINATES), size(RBSS_CONSTRAINTS));
            let (na, no) = (size(RBSS_ACTUATED), size(RBSS_OUTPUTS));
            let mut robot = Self {
                h: Handle(h),
                library_path: path.clone(),
                name: c_str((api.rbss_name)(h)),
                n,
                m,
                actuated: na,
                outputs: no,
                has_dynamics: size(RBSS_DYNAMICS) == 1,
                coordinates: (0..n).map(|i| c_str((api.rbss_coordinate)(h, i))).collect(),
                constraint_names: (0..m).map(|i| c_str((api.rbss_constraint)(h, i))).collect(),
                actuated_index: (0..na).map(|i| (api.rbss_actuated)(h, i)).collect(),
                output_index: (0..no).map(|i| (api.rbss_output)(h, i)).collect(),
                home: py.None(),
                api,
                _lib: lib,
            };
            let x = PyArrayDyn::<f64>::zeros(py, vec![n], false);
            robot.check(py, (robot.api.rbss_home)(h, x.data()))?;
            robot.home = x.into_any().unbind();
            Ok(robot)
        }
    }

    // ---- kinematics ----

    /// Every coordinate from the outputs (shape (outputs,) or (k, outputs)); each row starts
    /// from x_start (default: the home).
    #[pyo3(signature = (pose, x_start=None, out=None))]
    fn ik<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
        x_start: Option<&Bound<'py, PyAny>>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, len) = (self.api.rbss_ik, self.outputs);
        self.solve(py, f, (pose, len, "pose"), x_start, out)
    }

    /// Every coordinate from the actuated ones.
    #[pyo3(signature = (q, x_start=None, out=None))]
    fn fk<'py>(
        &self,
        py: Python<'py>,
        q: &Bound<'py, PyAny>,
        x_start: Option<&Bound<'py, PyAny>>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, len) = (self.api.rbss_fk, self.actuated);
        self.solve(py, f, (q, len, "q"), x_start, out)
    }

    /// Xdot from the output rates at x (inverse velocity).
    #[pyo3(signature = (x, pose_dot, out=None))]
    fn velocity<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        pose_dot: &Bound<'py, PyAny>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n, o) = (self.api.rbss_inverse_velocity, self.n, self.outputs);
        self.two(py, f, (x, n, "x"), (pose_dot, o, "pose_dot"), n, out)
    }

    /// Xdot from the actuated rates at x.
    #[pyo3(signature = (x, qdot, out=None))]
    fn forward_velocity<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        qdot: &Bound<'py, PyAny>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n, a) = (self.api.rbss_forward_velocity, self.n, self.actuated);
        self.two(py, f, (x, n, "x"), (qdot, a, "qdot"), n, out)
    }

    /// Xddot from the output accelerations at (x, xdot).
    #[pyo3(signature = (x, xdot, pose_ddot, out=None))]
    fn acceleration<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        xdot: &Bound<'py, PyAny>,
        pose_ddot: &Bound<'py, PyAny>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n, o) = (self.api.rbss_inverse_acceleration, self.n, self.outputs);
        let ins = [(x, n, "x"), (xdot, n, "xdot"), (pose_ddot, o, "pose_ddot")];
        let call = Call::new(py, &ins, &[], &[n], out)?;
        // SAFETY: as in `one`.
        self.rows(py, call, |h, c, r| unsafe {
            f(
                h,
                c.input(0, r),
                c.input(1, r),
                c.input(2, r),
                c.output(0, r),
            )
        })
    }

    /// Xddot from the actuated accelerations at (x, xdot).
    #[pyo3(signature = (x, xdot, qddot, out=None))]
    fn forward_acceleration<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        xdot: &Bound<'py, PyAny>,
        qddot: &Bound<'py, PyAny>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n, a) = (self.api.rbss_forward_acceleration, self.n, self.actuated);
        let ins = [(x, n, "x"), (xdot, n, "xdot"), (qddot, a, "qddot")];
        let call = Call::new(py, &ins, &[], &[n], out)?;
        // SAFETY: as in `one`.
        self.rows(py, call, |h, c, r| unsafe {
            f(
                h,
                c.input(0, r),
                c.input(1, r),
                c.input(2, r),
                c.output(0, r),
            )
        })
    }

    // ---- dynamics ----

    /// (U, lambda) for the motion (x, xdot, xddot).
    #[pyo3(signature = (x, xdot, xddot, out=None))]
    fn inverse_dynamics<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        xdot: &Bound<'py, PyAny>,
        xddot: &Bound<'py, PyAny>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n) = (self.api.rbss_inverse_dynamics, self.n);
        let ins = [(x, n, "x"), (xdot, n, "xdot"), (xddot, n, "xddot")];
        let call = Call::new(py, &ins, &[], &[self.actuated, self.m], out)?;
        // SAFETY: as in `one`.
        self.rows(py, call, |h, c, r| unsafe {
            f(
                h,
                c.input(0, r),
                c.input(1, r),
                c.input(2, r),
                c.output(0, r),
                c.output(1, r),
            )
        })
    }

    /// (Xddot, lambda) under the actuated forces u; (k, n) inputs loop in the library
    /// (rbss_forward_dynamics_batch). `out`: a tuple (xddot, lambda) of arrays to write.
    #[pyo3(signature = (x, xdot, u, out=None))]
    fn forward_dynamics<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        xdot: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let n = self.n;
        let ins = [(x, n, "x"), (xdot, n, "xdot"), (u, self.actuated, "u")];
        let call = Call::new(py, &ins, &[], &[n, self.m], out)?;
        let (h, c) = (self.h.0, &call);
        // SAFETY: as in `one`; the batch reads and writes k rows of each.
        let code = unsafe {
            if call.batched {
                (self.api.rbss_forward_dynamics_batch)(
                    h,
                    call.k,
                    c.input(0, 0),
                    c.input(1, 0),
                    c.input(2, 0),
                    c.output(0, 0),
                    c.output(1, 0),
                )
            } else {
                (self.api.rbss_forward_dynamics)(
                    h,
                    c.input(0, 0),
                    c.input(1, 0),
                    c.input(2, 0),
                    c.output(0, 0),
                    c.output(1, 0),
                )
            }
        };
        self.check(py, code)?;
        call.result(py)
    }

    /// (x, xdot) at t_end from (x0, xdot0) at 0 under constant forces u (default zero); (k, n)
    /// initial states are simulated one after the other. method: "dopri5" or "dop853"
    /// (Dormand-Prince 8(5,3): fewer steps at tight tolerances). An initial state with
    /// max |f(x0)| or max |G xdot0| above state_tol is an RbssError (code RBSS_ERR_STATE, the
    /// residual in the message) unless project=True, which projects it onto the constraints.
    /// full_output=True also returns [max |f(x0)|, max |G xdot0|, max |dX|, max |dXdot|] (per
    /// row): the residuals and how far the projection moved the state (rbss_simulate_checked).
    #[pyo3(signature = (x0, xdot0, t_end, u=None, rtol=1e-10, atol=1e-12, out=None, method="dopri5", state_tol=1e-6, project=false, full_output=false))]
    #[allow(clippy::too_many_arguments)]
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        x0: &Bound<'py, PyAny>,
        xdot0: &Bound<'py, PyAny>,
        t_end: f64,
        u: Option<&Bound<'py, PyAny>>,
        rtol: f64,
        atol: f64,
        out: Option<&Bound<'py, PyAny>>,
        method: &str,
        state_tol: f64,
        project: bool,
        full_output: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let code = match method {
            "dopri5" => RBSS_METHOD_DOPRI5,
            "dop853" => RBSS_METHOD_DOP853,
            other => {
                return Err(PyValueError::new_err(format!(
                    "method: expected 'dopri5' or 'dop853', got {other:?}"
                )));
            }
        };
        let (f, n) = (self.api.rbss_simulate_checked, self.n);
        // The check's numbers go to a third output, made here (`out` gives the first two).
        let given = match out {
            Some(o) if !o.is_none() => {
                let t = o
                    .cast::<PyTuple>()
                    .ok()
                    .filter(|t| t.len() == 2)
                    .ok_or_else(|| PyValueError::new_err("out: expected a tuple of 2 arrays"))?;
                Some(t.clone())
            }
            _ => None,
        };
        let first = contiguous(x0)?;
        let dim = if first.ndim() == 2 {
            IxDyn(&[first.shape()[0], 4])
        } else {
            IxDyn(&[4])
        };
        let state = PyArrayDyn::<f64>::zeros(py, dim, false);
        let outs = match &given {
            Some(t) => Some(
                PyTuple::new(
                    py,
                    [t.get_item(0)?, t.get_item(1)?, state.clone().into_any()],
                )?
                .into_any(),
            ),
            None => None,
        };
        let ins = [(x0, n, "x0"), (xdot0, n, "xdot0")];
        let shared = [(u, self.actuated, "u")];
        let call = match &outs {
            Some(o) => Call::new(py, &ins, &shared, &[n, n, 4], Some(o))?,
            None => {
                let mut call = Call::new(py, &ins, &shared, &[n, n], None)?;
                let data = state.data();
                call.outs.push((state.clone(), data, 4));
                call
            }
        };
        let project = c_int::from(project);
        // SAFETY: as in `one`; u is null or `actuated` values, the state output 4 per row.
        let result = self.rows(py, call, |h, c, r| unsafe {
            f(
                h,
                code,
                c.input(0, r),
                c.input(1, r),
                c.shared[0],
                t_end,
                rtol,
                atol,
                state_tol,
                project,
                c.output(0, r),
                c.output(1, r),
                c.output(2, r),
            )
        })?;
        let result = result.cast_into::<PyTuple>()?;
        let (x, xdot) = match given {
            Some(t) => (t.get_item(0)?, t.get_item(1)?),
            None => (result.get_item(0)?, result.get_item(1)?),
        };
        if full_output {
            Ok(PyTuple::new(py, [x, xdot, state.into_any()])?.into_any())
        } else {
            Ok(PyTuple::new(py, [x, xdot])?.into_any())
        }
    }

    /// [T, Pi].
    #[pyo3(signature = (x, xdot, out=None))]
    fn energy<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        xdot: &Bound<'py, PyAny>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n) = (self.api.rbss_energy, self.n);
        self.two(py, f, (x, n, "x"), (xdot, n, "xdot"), 2, out)
    }

    // ---- kernels ----

    /// f(X) (m values).
    #[pyo3(signature = (x, out=None))]
    fn constraints<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n, m) = (self.api.rbss_constraints, self.n, self.m);
        self.one(py, f, (x, n, "x"), m, out)
    }

    /// G = df/dX, shape (m, n) (or (k, m, n)).
    fn jacobian<'py>(&self, py: Python<'py>, x: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let (f, n, m) = (self.api.rbss_jacobian, self.n, self.m);
        self.matrix(py, f, x, m, n)
    }

    /// gamma = -(dG/dt) Xdot (m values).
    #[pyo3(signature = (x, xdot, out=None))]
    fn gamma<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        xdot: &Bound<'py, PyAny>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n, m) = (self.api.rbss_gamma, self.n, self.m);
        self.two(py, f, (x, n, "x"), (xdot, n, "xdot"), m, out)
    }

    /// M(X), shape (n, n) (or (k, n, n)).
    fn mass_matrix<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n) = (self.api.rbss_mass_matrix, self.n);
        self.matrix(py, f, x, n, n)
    }

    /// psi(X, Xdot) (n values).
    #[pyo3(signature = (x, xdot, out=None))]
    fn psi<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        xdot: &Bound<'py, PyAny>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n) = (self.api.rbss_psi, self.n);
        self.two(py, f, (x, n, "x"), (xdot, n, "xdot"), n, out)
    }

    // ---- derivatives ----

    /// Forward dynamics at (x, xdot, u) and its derivatives (rbss_forward_dynamics_derivatives):
    /// a dict of "xddot" (n,), "lambda" (m,), "dxddot_dx", "dxddot_dxdot" (n, n), "dxddot_du"
    /// (n, actuated), "dlambda_dx", "dlambda_dxdot" (m, n), "dlambda_du" (m, actuated); (k, n)
    /// inputs give each a leading axis k.
    fn forward_dynamics_derivatives<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        xdot: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n, m, a) = (
            self.api.rbss_forward_dynamics_derivatives,
            self.n,
            self.m,
            self.actuated,
        );
        let ins = [(x, n, "x"), (xdot, n, "xdot"), (u, a, "u")];
        let shapes = [
            (n, None),
            (m, None),
            (n, Some(n)),
            (n, Some(n)),
            (n, Some(a)),
            (m, Some(n)),
            (m, Some(n)),
            (m, Some(a)),
        ];
        let keys = [
            "xddot",
            "lambda",
            "dxddot_dx",
            "dxddot_dxdot",
            "dxddot_du",
            "dlambda_dx",
            "dlambda_dxdot",
            "dlambda_du",
        ];
        self.derivative_dict(py, f, &ins, &shapes, keys)
    }

    /// Inverse dynamics at the motion (x, xdot, xddot) and its derivatives
    /// (rbss_inverse_dynamics_derivatives): a dict of "u" (actuated,), "lambda" (m,), "du_dx",
    /// "du_dxdot", "du_dxddot" (actuated, n), "dlambda_dx", "dlambda_dxdot", "dlambda_dxddot"
    /// (m, n); (k, n) inputs give each a leading axis k.
    fn inverse_dynamics_derivatives<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        xdot: &Bound<'py, PyAny>,
        xddot: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (f, n, m, a) = (
            self.api.rbss_inverse_dynamics_derivatives,
            self.n,
            self.m,
            self.actuated,
        );
        let ins = [(x, n, "x"), (xdot, n, "xdot"), (xddot, n, "xddot")];
        let shapes = [
            (a, None),
            (m, None),
            (a, Some(n)),
            (a, Some(n)),
            (a, Some(n)),
            (m, Some(n)),
            (m, Some(n)),
            (m, Some(n)),
        ];
        let keys = [
            "u",
            "lambda",
            "du_dx",
            "du_dxdot",
            "du_dxddot",
            "dlambda_dx",
            "dlambda_dxdot",
            "dlambda_dxddot",
        ];
        self.derivative_dict(py, f, &ins, &shapes, keys)
    }

    /// (A, B) of d/dt [y; ydot] = A [y; ydot] + B U, forward dynamics linearised on the
    /// constraint manifold at (x, xdot, u) (rbss_linearize) in the d = n - m independent
    /// coordinates y: "outputs" (output_index's) or "actuated" (actuated_index's, fully
    /// actuated robots). A (2d, 2d), B (2d, actuated); (k, n) inputs give (k, 2d, 2d) and
    /// (k, 2d, actuated). A state off the manifold (max |f(x)| or max |G xdot| above 1e-6) is
    /// an RbssError with code RBSS_ERR_STATE.
    #[pyo3(signature = (x, xdot, u, coordinates="outputs"))]
    fn linearize<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        xdot: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
        coordinates: &str,
    ) -> PyResult<Bound<'py, PyAny>> {
        let code = match coordinates {
            "outputs" => RBSS_LINEARIZE_OUTPUTS,
            "actuated" => RBSS_LINEARIZE_ACTUATED,
            other => {
                return Err(PyValueError::new_err(format!(
                    "coordinates: expected 'outputs' or 'actuated', got '{other}'"
                )));
            }
        };
        let (f, n, a) = (self.api.rbss_linearize, self.n, self.actuated);
        let w = 2 * n.saturating_sub(self.m);
        let ins = [(x, n, "x"), (xdot, n, "xdot"), (u, a, "u")];
        // SAFETY: as in `one`.
        let outs = self.shaped_rows(py, &ins, &[(w, Some(w)), (w, Some(a))], |h, c, r| unsafe {
            f(
                h,
                code,
                c.input(0, r),
                c.input(1, r),
                c.input(2, r),
                c.output(0, r),
                c.output(1, r),
            )
        })?;
        Ok(PyTuple::new(py, outs)?.into_any())
    }

    /// One step of h > 0 from the state s = (x, xdot) with u held over it, and its Jacobians
    /// (rbss_step_derivatives): (x_next, xdot_next, F_x, F_u), F_x = ds'/ds (2n, 2n; s = (X,
    /// Xdot) in that order), F_u = ds'/dU (2n, actuated). method: "rk4" or
    /// "semi_implicit_euler"; baumgarte: [alpha, beta] gains on each stage's acceleration
    /// (default none). (k, n) inputs give each result a leading axis k.
    #[pyo3(signature = (x, xdot, u, h, method="rk4", baumgarte=None))]
    #[allow(clippy::too_many_arguments)]
    fn step_derivatives<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        xdot: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
        h: f64,
        method: &str,
        baumgarte: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let code = match method {
            "rk4" => RBSS_STEP_RK4,
            "semi_implicit_euler" => RBSS_STEP_SEMI_IMPLICIT_EULER,
            other => {
                return Err(PyValueError::new_err(format!(
                    "method: expected 'rk4' or 'semi_implicit_euler', got '{other}'"
                )));
            }
        };
        let (f, n, a) = (self.api.rbss_step_derivatives, self.n, self.actuated);
        let gains = match baumgarte {
            Some(b) if !b.is_none() => {
                let g = contiguous(b)?;
                if g.shape() != [2] {
                    return Err(PyValueError::new_err(format!(
                        "baumgarte: expected shape (2,), got {}",
                        shape_repr(g.shape())
                    )));
                }
                Some(g)
            }
            _ => None,
        };
        let g: In = gains.as_ref().map_or(std::ptr::null(), |g| g.data() as In);
        let ins = [(x, n, "x"), (xdot, n, "xdot"), (u, a, "u")];
        let shapes = [(n, None), (n, None), (2 * n, Some(2 * n)), (2 * n, Some(a))];
        // SAFETY: as in `one`; `g` is null or 2 values, kept alive by `gains`.
        let outs = self.shaped_rows(py, &ins, &shapes, |hd, c, r| unsafe {
            f(
                hd,
                code,
                c.input(0, r),
                c.input(1, r),
                c.input(2, r),
                h,
                g,
                c.output(0, r),
                c.output(1, r),
                c.output(2, r),
                c.output(3, r),
            )
        })?;
        Ok(PyTuple::new(py, outs)?.into_any())
    }
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("ABI_VERSION", ABI_VERSION)?;
    m.add_class::<Robot>()
}
