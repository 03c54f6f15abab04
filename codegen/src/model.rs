//! The validated model: what `parse` produces from a model file and `derive` consumes.
//!
//! Every name is resolved to an index and every expression to an [`Expr`] tree; positions
//! ([`Pos`]) point back into the model file for messages raised after parsing.

pub use crate::diagnostics::Pos;

/// A source file that a model was imported from, as the generated header records it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SourceFile {
    /// The path as shown (relative to the working directory, like the model's).
    pub path: String,
    /// sha256 of its LF-normalised bytes (the files it includes hashed after it).
    pub sha256: String,
}

/// A validated robot model.
#[derive(Debug, Clone)]
pub struct Model {
    /// `[robot] name`: the generated crate's name (snake_case).
    pub name: String,
    /// `[robot] description`.
    pub description: String,
    /// Parameters in file order; an expression refers only to earlier parameters.
    pub parameters: Vec<Parameter>,
    /// Coordinates `X` in file order.
    pub coordinates: Vec<Coordinate>,
    /// Indices of the actuated coordinates `q`, in the order of `[robot] actuated`.
    pub actuated: Vec<usize>,
    /// Indices of the output (task) coordinates, in the order of `[robot] outputs`.
    pub outputs: Vec<usize>,
    /// Gravity in the world frame (parameter expressions).
    pub gravity: [Expr; 3],
    /// Bodies (frames, with or without mass) in file order; a parent comes before its children.
    pub bodies: Vec<Body>,
    /// Loop-closure constraints in file order.
    pub loops: Vec<Loop>,
    /// The source the model was imported from (`urdf = "..."`), `None` for a plain model.
    pub import: Option<Import>,
}

/// A model imported from a URDF, MJCF or SDF file (`crate::import`).
#[derive(Debug, Clone)]
pub struct Import {
    /// The source file as the generated header records it (path, sha256).
    pub source: SourceFile,
    /// The text the model was parsed from: the model file, then the imported model. Positions
    /// in the model (`Pos`) are in this text.
    pub text: String,
    /// The length of the model file's own text at the start of `text`.
    pub model_len: usize,
    /// Where `text`'s imported lines come from: the source's elements.
    pub map: crate::source::SourceMap,
}

/// A named parameter.
#[derive(Debug, Clone)]
pub struct Parameter {
    pub name: String,
    /// The value as written (numbers are exact decimals), in SI units; a `deg` value is
    /// already multiplied by `pi/180`.
    pub expr: Expr,
    /// `expr` evaluated in f64: the default of the generated `Params`.
    pub value: f64,
    /// The unit as written (`"m"`, `"deg"`, `"kg"`...), for documentation.
    pub unit: String,
    /// Optional documentation string.
    pub doc: String,
    pub pos: Pos,
}

/// A generalised coordinate.
#[derive(Debug, Clone)]
pub struct Coordinate {
    pub name: String,
    /// `"m"`, `"rad"` (a `deg` home value is converted to rad) or `"1"` (dimensionless: a
    /// `free` joint's quaternion).
    pub unit: String,
    /// Reference-assembly value: the solvers' cold start.
    pub home: f64,
    /// The forces of the joint this coordinate moves (all `None`: none).
    pub forces: JointForces,
    /// An actuated coordinate's gear ratio (`gear`, nonzero): its actuator's `U` is in the
    /// motor's units and the force on the coordinate is `gear * U`. `None`: `U` is the force.
    pub gear: Option<f64>,
    pub pos: Pos,
}

/// A joint's own forces on its coordinate `q` (parameter expressions, SI units per metre or
/// per radian of `q`), as MuJoCo's `stiffness`/`springref`/`damping`/`armature`:
///
/// - a spring `-stiffness (q - rest)` with potential `½ stiffness (q - rest)²` (in `Pi`);
/// - a viscous damper `-damping q̇` (in `psi`, not from a potential);
/// - `armature`, an inertia added to `M`'s diagonal entry of `q` (kinetic energy
///   `½ armature q̇²`): a rotor's inertia seen at the joint (`gear² J_rotor` behind a gear).
#[derive(Debug, Clone, Default)]
pub struct JointForces {
    /// Spring stiffness `k` (N/m or N m/rad), `>= 0`.
    pub stiffness: Option<Expr>,
    /// The spring's rest value of `q` (m or rad); `0` when not given.
    pub rest: Option<Expr>,
    /// Viscous damping `c` (N s/m or N m s/rad), `>= 0`.
    pub damping: Option<Expr>,
    /// Armature inertia (kg or kg m²), `>= 0`.
    pub armature: Option<Expr>,
}

impl JointForces {
    /// True when the joint has none of these forces.
    pub fn is_empty(&self) -> bool {
        self.stiffness.is_none() && self.damping.is_none() && self.armature.is_none()
    }
}

/// A coordinate axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Axis::X => "x",
            Axis::Y => "y",
            Axis::Z => "z",
        }
    }
}

/// One elementary homogeneous transform, composed by post-multiplication (about or along the
/// axes of the frame reached so far). The paper's 12-element pose vector is expanded by the
/// parser into six of these in the order it gives.
#[derive(Debug, Clone)]
pub enum Step {
    /// `Rx(a)`, `Ry(a)`, `Rz(a)`.
    Rot(Axis, Expr),
    /// `Tx(s)`, `Ty(s)`, `Tz(s)`.
    Trans(Axis, Expr),
    /// A constant rotation by the matrix `R` (`R[i][j]`: row i, column j; a vector's
    /// components in the frame before the step are `R ·` its components after it), from a
    /// `quat` or `axis_angle` step. Its entries are parameter expressions (no coordinate).
    Rotation(Box<[[Expr; 3]; 3]>),
    /// A rotation by the quaternion `w + x i + y j + z k` of four coordinates (a `free` joint's
    /// orientation), normalised: `R(q / |q|)`, so that it is a rotation at every `q != 0` and
    /// its body-axes angular velocity is `2 Im(q* q̇) / |q|²` exactly. Its unit norm is a
    /// constraint of `f` (a [`LoopKind::UnitNorm`] loop).
    Quat(Box<[Expr; 4]>),
}

/// The rotation matrix of the quaternion `q = [w, x, y, z]` normalised (`R(q / |q|)`, as a
/// [`Step::Quat`] turns): with `s = 2 / |q|²`, `R = 1 - s (...)`.
pub fn quat_rotation(q: [f64; 4]) -> [[f64; 3]; 3] {
    let [w, x, y, z] = q;
    let s = 2.0 / (w * w + x * x + y * y + z * z);
    [
        [
            1.0 - s * (y * y + z * z),
            s * (x * y - w * z),
            s * (x * z + w * y),
        ],
        [
            s * (x * y + w * z),
            1.0 - s * (x * x + z * z),
            s * (y * z - w * x),
        ],
        [
            s * (x * z - w * y),
            s * (y * z + w * x),
            1.0 - s * (x * x + y * y),
        ],
    ]
}

/// A rigid body (or a massless frame): its frame relative to its parent's.
#[derive(Debug, Clone)]
pub struct Body {
    pub name: String,
    /// Index into `Model::bodies`; `None` is the world frame.
    pub parent: Option<usize>,
    /// Frame of this body = parent frame * `steps[0]` * `steps[1]` * ...
    pub steps: Vec<Step>,
    /// Mass properties; `None` for a massless frame.
    pub inertia: Option<MassProps>,
    pub pos: Pos,
}

/// Mass properties of a body, as parameter expressions.
#[derive(Debug, Clone)]
pub struct MassProps {
    pub mass: Expr,
    /// Centre of mass in the body frame.
    pub com: [Expr; 3],
    /// Inertia about the centre of mass in the body axes: `[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`.
    pub inertia: [Expr; 6],
}

/// A point attached to a body: the origin of `body * steps`.
#[derive(Debug, Clone)]
pub struct Attachment {
    /// `None` is the world frame.
    pub body: Option<usize>,
    pub steps: Vec<Step>,
}

/// A loop closure (`[[loop]]`): equations between two attachments `a` and `b` (or, for a
/// coupling, between two expressions of the coordinates), by [`LoopKind`].
#[derive(Debug, Clone)]
pub struct Loop {
    pub name: String,
    pub a: Attachment,
    pub b: Attachment,
    /// The components of `origin(a) - origin(b)` that are equations (along the axes of
    /// `frame`); all three unless the model says otherwise. Empty for `distance` and `coupling`.
    pub components: Vec<Axis>,
    /// The axes `components` are taken along: the world's (`None`), or those of the frame of
    /// attachment `a` (`Some(Side::A)`) or `b`.
    pub frame: Option<Side>,
    pub kind: LoopKind,
    pub pos: Pos,
}

/// One of a loop's two attachments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    A,
    B,
}

/// What a loop makes equal (see docs/model-format.md for the equations and their signs).
#[derive(Debug, Clone)]
pub enum LoopKind {
    /// `point` (alias `ball`): the two origins coincide along `components`; the components left
    /// out are checked after every position solve (they must close too).
    Point,
    /// `point_in_plane` / `point_on_line`: as `Point`, but the components left out are free
    /// (the origin of `b` slides in a plane or along a line of the frame).
    Sliding,
    /// `weld`: the two frames coincide, orientation too (three more equations, the rotation
    /// between them, see `derive`).
    Weld,
    /// `hinge`: the origins coincide along `components` and axis `axis` of the two frames is
    /// the same line direction (two more equations: axis `axis` of `b` has no component along
    /// the other two axes of `a`).
    Hinge(Axis),
    /// `distance`: `|origin(a) - origin(b)| = length` (one equation,
    /// `(|d|² - length²) / (2 length)`).
    Distance(Expr),
    /// `coupling`: `a = poly[0] + poly[1] b + poly[2] b² + …` between two expressions of the
    /// coordinates (a coordinate, a fixed tendon's length `2 q1 + 0.5 q3`), one equation
    /// `a - p(b)`; `ratio` and `offset` are `poly = [offset, ratio]`. Without `b`, `a = poly[0]`
    /// (`poly` has one entry).
    Coupling {
        a: Expr,
        b: Option<Expr>,
        poly: Vec<Expr>,
    },
    /// `unit_norm`: a `free` joint's quaternion `q = X[i0..i3]` has unit norm (one equation,
    /// `(qᵀq - 1) / 2`, whose gradient is `qᵀ`). The parser adds one per `free` joint.
    UnitNorm([usize; 4]),
}

impl Loop {
    /// The number of equations the loop adds to `f`.
    pub fn equations(&self) -> usize {
        self.components.len()
            + match self.kind {
                LoopKind::Point | LoopKind::Sliding => 0,
                LoopKind::Weld => 3,
                LoopKind::Hinge(_) => 2,
                LoopKind::Distance(_) | LoopKind::Coupling { .. } | LoopKind::UnitNorm(_) => 1,
            }
    }

    /// True for the kinds whose equations relate two attachments (all but `coupling`).
    pub fn is_geometric(&self) -> bool {
        !matches!(self.kind, LoopKind::Coupling { .. } | LoopKind::UnitNorm(_))
    }

    /// The weld's three rotation rows.
    pub fn is_weld(&self) -> bool {
        matches!(self.kind, LoopKind::Weld)
    }
}

/// Built-in functions of the expression language: the table shared with trajectories
/// (`rbss_expr::Func`).
pub use rbss_expr::Func;

/// Rust's keywords (strict, reserved and weak ones that cannot name an item): names become
/// Rust identifiers, so a model cannot use them (the parser refuses them, the importers map
/// them, see `import::ident`).
pub const RUST_KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut",
    "pub", "ref", "return", "self", "Self", "static", "struct", "super", "trait", "true", "type",
    "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "try", "typeof", "unsized", "virtual", "yield", "_",
];

/// An expression of the model language. Numbers are exact: a decimal literal `0.489` is the
/// rational `489/1000`.
#[derive(Debug, Clone, PartialEq)]
pub enum Expr {
    /// An exact rational `num / den`, `den > 0`.
    Num {
        num: i128,
        den: i128,
    },
    /// The constant pi.
    Pi,
    /// A parameter (index into `Model::parameters`).
    Param(usize),
    /// A coordinate (index into `Model::coordinates`).
    Coord(usize),
    Neg(Box<Expr>),
    Add(Box<Expr>, Box<Expr>),
    Sub(Box<Expr>, Box<Expr>),
    Mul(Box<Expr>, Box<Expr>),
    Div(Box<Expr>, Box<Expr>),
    /// `base ^ exponent`.
    Pow(Box<Expr>, Box<Expr>),
    /// `f(args)`, [`Func::arity`] arguments.
    Call(Func, Vec<Expr>),
}

impl Expr {
    pub fn int(n: i128) -> Expr {
        Expr::Num { num: n, den: 1 }
    }

    /// True when the expression involves no coordinate (only numbers, pi and parameters).
    pub fn is_constant(&self) -> bool {
        match self {
            Expr::Num { .. } | Expr::Pi | Expr::Param(_) => true,
            Expr::Coord(_) => false,
            Expr::Neg(a) => a.is_constant(),
            Expr::Call(_, args) => args.iter().all(Expr::is_constant),
            Expr::Add(a, b)
            | Expr::Sub(a, b)
            | Expr::Mul(a, b)
            | Expr::Div(a, b)
            | Expr::Pow(a, b) => a.is_constant() && b.is_constant(),
        }
    }

    /// Calls `f` with the index of every parameter the expression reads (once per occurrence).
    pub fn for_each_param(&self, f: &mut impl FnMut(usize)) {
        match self {
            Expr::Param(j) => f(*j),
            Expr::Num { .. } | Expr::Pi | Expr::Coord(_) => {}
            Expr::Neg(a) => a.for_each_param(f),
            Expr::Call(_, args) => args.iter().for_each(|a| a.for_each_param(f)),
            Expr::Add(a, b)
            | Expr::Sub(a, b)
            | Expr::Mul(a, b)
            | Expr::Div(a, b)
            | Expr::Pow(a, b) => {
                a.for_each_param(f);
                b.for_each_param(f);
            }
        }
    }

    /// Evaluates in f64 with the given parameter values (coordinates evaluate to `coords[i]`).
    pub fn eval(&self, params: &[f64], coords: &[f64]) -> f64 {
        match self {
            Expr::Num { num, den } => *num as f64 / *den as f64,
            Expr::Pi => std::f64::consts::PI,
            Expr::Param(i) => params[*i],
            Expr::Coord(i) => coords[*i],
            Expr::Neg(a) => -a.eval(params, coords),
            Expr::Add(a, b) => a.eval(params, coords) + b.eval(params, coords),
            Expr::Sub(a, b) => a.eval(params, coords) - b.eval(params, coords),
            Expr::Mul(a, b) => a.eval(params, coords) * b.eval(params, coords),
            Expr::Div(a, b) => a.eval(params, coords) / b.eval(params, coords),
            Expr::Pow(a, b) => a.eval(params, coords).powf(b.eval(params, coords)),
            Expr::Call(f, args) => {
                let v: Vec<f64> = args.iter().map(|a| a.eval(params, coords)).collect();
                f.eval(&v)
            }
        }
    }
}
