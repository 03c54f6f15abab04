//! Task frames as outputs: `outputs = [{ frame = "tool0", pose = "xyz-rpy" }]` (or
//! `position = true`) names a body's frame instead of coordinates. The parser adds, after the
//! model's own coordinates, the frame's pose as output coordinates — `tool0_x`, `tool0_y`,
//! `tool0_z` (m) and, for a pose, `tool0_roll`, `tool0_pitch`, `tool0_yaw` (rad, URDF's rpy:
//! `R = Rz(yaw) Ry(pitch) Rx(roll)`) — and one closure that ties them to the frame: a `weld`
//! (six equations) or a `point` loop (three) between the body and the world frame moved by
//! those coordinates. No body is added (no mass, no kinetic energy): the output functions
//! `y = h(X)`, their Jacobian and their velocity-product terms are rows of `f`, `G` and `gamma`,
//! derived on the same graph as every other kernel, and inverse kinematics, forward kinematics
//! and trajectories work on them unchanged. Their home is the frame's pose at the home of the
//! other coordinates (evaluated here), so the assembly moves nothing.

use super::*;
use crate::import::geom::{Mat as M3, elementary, mul};

/// What a task frame outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum FrameKind {
    /// Position and URDF rpy angles: six coordinates, a weld.
    Pose,
    /// The origin only: three coordinates, a point loop.
    Position,
}

impl FrameKind {
    fn suffixes(self) -> &'static [&'static str] {
        match self {
            FrameKind::Pose => &["x", "y", "z", "roll", "pitch", "yaw"],
            FrameKind::Position => &["x", "y", "z"],
        }
    }
}

/// One `{ frame = ... }` entry of `outputs`, before the bodies are known.
#[derive(Debug, Clone)]
pub(super) struct FrameOutput {
    pub(super) frame: String,
    pub(super) frame_span: Span,
    pub(super) kind: FrameKind,
    /// The coordinates' and the loop's name prefix (`name`, or the frame's name).
    pub(super) prefix: String,
    pub(super) span: Span,
    /// Index of its first coordinate in `X`.
    pub(super) first: usize,
}

pub(super) const FRAME_OUTPUT_KEYS: &[&str] = &["frame", "pose", "position", "name"];

/// The world pose (rotation, origin) of body `b`'s frame, evaluated in f64.
fn world_pose(bodies: &[Body], b: usize, params: &[f64], coords: &[f64]) -> (M3, [f64; 3]) {
    let (mut r, mut p) = match bodies[b].parent {
        Some(parent) if parent < b => world_pose(bodies, parent, params, coords),
        _ => (
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            [0.0; 3],
        ),
    };
    for step in &bodies[b].steps {
        match step {
            Step::Rot(axis, e) => r = mul(&r, &elementary(axis.index(), e.eval(params, coords))),
            Step::Trans(axis, e) => {
                let s = e.eval(params, coords);
                for (i, pi) in p.iter_mut().enumerate() {
                    *pi += r[i][axis.index()] * s;
                }
            }
            Step::Rotation(m) => {
                let m: M3 =
                    std::array::from_fn(|i| std::array::from_fn(|j| m[i][j].eval(params, coords)));
                r = mul(&r, &m);
            }
            Step::Quat(q) => {
                let q = std::array::from_fn(|i| q[i].eval(params, coords));
                r = mul(&r, &crate::model::quat_rotation(q));
            }
        }
    }
    (r, p)
}

/// URDF's rpy of a rotation `R = Rz(yaw) Ry(pitch) Rx(roll)`, pitch in `[-pi/2, pi/2]`.
fn rpy(r: &M3) -> [f64; 3] {
    [
        r[2][1].atan2(r[2][2]),
        (-r[2][0]).atan2(r[0][0].hypot(r[1][0])),
        r[1][0].atan2(r[0][0]),
    ]
}

impl Parser<'_> {
    /// An `outputs` entry written as a table: a task frame. Returns the indices of the
    /// coordinates it adds (allocated after the model's own and earlier frames').
    pub(super) fn frame_output(&mut self, item: &Value<'_>) -> Option<Vec<usize>> {
        let what = "a task frame in `outputs`";
        let t = self.table(item, what)?;
        let span = item.span();
        self.check_keys(t, &span, FRAME_OUTPUT_KEYS, "a task frame of `outputs`");
        let frame_v = self.required(t, &span, "frame", "a task frame of `outputs`")?;
        let frame = self.string(frame_v, "the `frame` of a task frame")?;
        let kind = match (get(t, "pose"), get(t, "position")) {
            (Some(pv), None) => match pv.get_ref() {
                DeValue::String(s) if s.as_ref() == "xyz-rpy" => FrameKind::Pose,
                _ => {
                    let d = self.cx.error(
                        &pv.span(),
                        "unknown pose parametrisation".to_string(),
                        "expected \"xyz-rpy\"",
                    );
                    d.help = Some(
                        "`pose = \"xyz-rpy\"`: the origin's x, y, z and URDF's roll, pitch, yaw \
                         (R = Rz(yaw) Ry(pitch) Rx(roll)); `position = true` for the origin only"
                            .to_string(),
                    );
                    return None;
                }
            },
            (None, Some(pv)) => match pv.get_ref() {
                DeValue::Boolean(true) => FrameKind::Position,
                _ => {
                    self.cx.error(
                        &pv.span(),
                        "`position` of a task frame must be `true`".to_string(),
                        "expected `true`",
                    );
                    return None;
                }
            },
            (Some(_), Some(pv)) => {
                let d = self.cx.error(
                    &pv.span(),
                    format!("task frame `{frame}` gives both `pose` and `position`"),
                    "one of them",
                );
                d.help = Some(
                    "`pose = \"xyz-rpy\"` outputs the position and the orientation, \
                     `position = true` the position only"
                        .to_string(),
                );
                return None;
            }
            (None, None) => {
                let d = self.cx.error(
                    &span,
                    format!("task frame `{frame}` says neither `pose` nor `position`"),
                    "what of the frame is an output?",
                );
                d.help = Some(format!(
                    "write `{{ frame = \"{frame}\", pose = \"xyz-rpy\" }}` (position and URDF rpy \
                     angles) or `{{ frame = \"{frame}\", position = true }}`"
                ));
                return None;
            }
        };
        let prefix = match get(t, "name") {
            Some(nv) => self.name(nv, "task frame")?,
            None => frame.clone(),
        };
        if let Some(other) = self.frame_outputs.iter().find(|f| f.prefix == prefix) {
            let line = self.cx.line(&other.span);
            let d = self.cx.error(
                &span,
                format!("task frame `{prefix}` is listed twice in `outputs`"),
                "listed again here",
            );
            d.help = Some(format!(
                "first listed on line {line}; to output two poses of one body, give one a \
                 `name = \"...\"` (the prefix of its coordinates)"
            ));
            return None;
        }
        for s in kind.suffixes() {
            let name = format!("{prefix}_{s}");
            if let Some(sym) = self.syms.get(&name) {
                let line = sym.line;
                let d = self.cx.error(
                    &span,
                    format!("task frame `{prefix}` adds coordinate `{name}`, but line {line} already names `{name}`"),
                    "its coordinates would clash",
                );
                d.help =
                    Some("give the task frame another prefix with `name = \"...\"`".to_string());
                return None;
            }
        }
        let first = self.coord_count
            + self
                .frame_outputs
                .iter()
                .map(|f| f.kind.suffixes().len())
                .sum::<usize>();
        let count = kind.suffixes().len();
        self.frame_outputs.push(FrameOutput {
            frame,
            frame_span: frame_v.span(),
            kind,
            prefix,
            span,
            first,
        });
        Some((first..first + count).collect())
    }

    /// Adds the task frames' coordinates and closures to the parsed model (see the module
    /// documentation). `false` after an error (an unknown body, a loop name taken).
    pub(super) fn expand_frame_outputs(
        &mut self,
        coords: &mut Vec<Coordinate>,
        bodies: &[Body],
        loops: &mut Vec<Loop>,
    ) -> bool {
        let mut ok = true;
        let params = self.param_values.clone();
        for f in std::mem::take(&mut self.frame_outputs) {
            let Some(b) = self.bodies.get(&f.frame).map(|i| i.index) else {
                let help = self.body_suggestion(&f.frame);
                let d = self.cx.error(
                    &f.frame_span,
                    format!("task frame names unknown body `{}`", f.frame),
                    "not a body of this model",
                );
                d.help = help.or_else(|| {
                    Some(
                        "`frame` names a body (a URDF link, an MJCF body, an SDF link)".to_string(),
                    )
                });
                ok = false;
                continue;
            };
            let loop_name = match f.kind {
                FrameKind::Pose => format!("{}_pose", f.prefix),
                FrameKind::Position => format!("{}_position", f.prefix),
            };
            if loops.iter().any(|l| l.name == loop_name) {
                let d = self.cx.error(
                    &f.span,
                    format!("task frame `{}` adds loop `{loop_name}`, but the model has a loop of that name", f.prefix),
                    "its closure would clash",
                );
                d.help =
                    Some("give the task frame another prefix with `name = \"...\"`".to_string());
                ok = false;
                continue;
            }
            if coords.len() != f.first || bodies.len() <= b {
                // An earlier error left the coordinates short: nothing sound to add.
                ok = false;
                continue;
            }
            let home: Vec<f64> = coords.iter().map(|c| c.home).collect();
            let (r, p) = world_pose(bodies, b, &params, &home);
            let angles = rpy(&r);
            let pos = self.cx.pos(f.span.start);
            for (k, s) in f.kind.suffixes().iter().enumerate() {
                coords.push(Coordinate {
                    name: format!("{}_{s}", f.prefix),
                    unit: if k < 3 { "m" } else { "rad" }.to_string(),
                    home: if k < 3 { p[k] } else { angles[k - 3] },
                    forces: JointForces::default(),
                    gear: None,
                    pos,
                });
            }
            let c = |k: usize| Expr::Coord(f.first + k);
            let mut steps = vec![
                Step::Trans(Axis::X, c(0)),
                Step::Trans(Axis::Y, c(1)),
                Step::Trans(Axis::Z, c(2)),
            ];
            if f.kind == FrameKind::Pose {
                steps.extend([
                    Step::Rot(Axis::Z, c(5)),
                    Step::Rot(Axis::Y, c(4)),
                    Step::Rot(Axis::X, c(3)),
                ]);
            }
            loops.push(Loop {
                name: loop_name,
                a: Attachment {
                    body: Some(b),
                    steps: Vec::new(),
                },
                b: Attachment { body: None, steps },
                components: vec![Axis::X, Axis::Y, Axis::Z],
                frame: None,
                kind: match f.kind {
                    FrameKind::Pose => LoopKind::Weld,
                    FrameKind::Position => LoopKind::Point,
                },
                pos,
            });
            self.loop_sites.push([f.frame_span.clone(), f.span.clone()]);
        }
        ok
    }
}
