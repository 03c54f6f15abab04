//! The little rotation arithmetic the importers do in f64: an inertia turned into a body's axes,
//! the turn that takes z onto a joint's axis, quaternions.

pub(crate) type Mat = [[f64; 3]; 3];

pub(crate) fn mul(a: &Mat, b: &Mat) -> Mat {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

pub(crate) fn transpose(a: &Mat) -> Mat {
    let mut t = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            t[i][j] = a[j][i];
        }
    }
    t
}

/// The elementary rotation about axis `k` (0 = x) by `t`.
pub(crate) fn elementary(k: usize, t: f64) -> Mat {
    let (s, c) = t.sin_cos();
    match k {
        0 => [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
        1 => [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        _ => [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
    }
}

/// URDF's roll-pitch-yaw: `Rz(y) Ry(p) Rx(r)`.
pub(crate) fn rpy(r: f64, p: f64, y: f64) -> Mat {
    mul(
        &elementary(2, y),
        &mul(&elementary(1, p), &elementary(0, r)),
    )
}

/// The rotation of the quaternion `w + x i + y j + z k` (normalised).
pub(crate) fn quat(q: [f64; 4]) -> Mat {
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let [w, x, y, z] = q.map(|v| v / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// The unit quaternion `[w, x, y, z]` of a rotation matrix (Shepperd's method).
pub(crate) fn to_quat(m: &Mat) -> [f64; 4] {
    let tr = m[0][0] + m[1][1] + m[2][2];
    let q = if tr > 0.0 {
        let s = (tr + 1.0).sqrt() * 2.0;
        [
            0.25 * s,
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][2] - m[2][0]) / s,
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[1][0] - m[0][1]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
        ]
    };
    if q[0] < 0.0 { q.map(|v| -v) } else { q }
}

pub(crate) fn apply(m: &Mat, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| (0..3).map(|k| m[i][k] * v[k]).sum())
}

/// `R I Rᵀ`: an inertia given in a frame turned by `R` from the body's, in the body's axes.
pub(crate) fn rotate_inertia(r: &Mat, i: &Mat) -> Mat {
    mul(r, &mul(i, &transpose(r)))
}

/// `[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]` of a symmetric matrix.
pub(crate) fn inertia_entries(i: &Mat) -> [f64; 6] {
    [i[0][0], i[1][1], i[2][2], i[0][1], i[0][2], i[1][2]]
}

/// The symmetric matrix of `[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`.
pub(crate) fn inertia_matrix(e: [f64; 6]) -> Mat {
    [[e[0], e[3], e[4]], [e[3], e[1], e[5]], [e[4], e[5], e[2]]]
}

/// The joint step for a unit axis in a body's frame: `Some((k, sign))` when it is `±` the
/// coordinate axis `k`; else `None` (a general axis).
pub(crate) fn coordinate_axis(a: [f64; 3]) -> Option<(usize, f64)> {
    (0..3).find_map(|k| {
        let others = (0..3).filter(|&j| j != k).all(|j| a[j] == 0.0);
        (others && a[k] != 0.0).then(|| (k, a[k].signum()))
    })
}

/// `[ax, ay, az, angle]` of the turn that takes z onto the unit vector `a` (not `±z`).
pub(crate) fn z_onto(a: [f64; 3]) -> [f64; 4] {
    // z × a = (-a_y, a_x, 0), angle acos(a_z).
    [-a[1], a[0], 0.0, a[2].clamp(-1.0, 1.0).acos()]
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
