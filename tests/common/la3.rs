//! 3-vectors and 3 × 3 matrices (row-major) for the tests' closed-form oracles, written out so
//! that the oracles share no code with the runtime or the generated kernels.

pub type M3 = [[f64; 3]; 3];
pub type V3 = [f64; 3];

pub fn mat_mul(a: &M3, b: &M3) -> M3 {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}
pub fn mat_vec(a: &M3, v: &V3) -> V3 {
    std::array::from_fn(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}
/// `aᵀ v`.
pub fn mat_t_vec(a: &M3, v: &V3) -> V3 {
    std::array::from_fn(|i| (0..3).map(|k| a[k][i] * v[k]).sum())
}
pub fn rx(t: f64) -> M3 {
    let (s, c) = t.sin_cos();
    [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]
}
pub fn ry(t: f64) -> M3 {
    let (s, c) = t.sin_cos();
    [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
}
pub fn rz(t: f64) -> M3 {
    let (s, c) = t.sin_cos();
    [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
}
pub fn add(a: &V3, b: &V3) -> V3 {
    std::array::from_fn(|i| a[i] + b[i])
}
pub fn sub(a: &V3, b: &V3) -> V3 {
    std::array::from_fn(|i| a[i] - b[i])
}
pub fn scale(s: f64, a: &V3) -> V3 {
    a.map(|x| s * x)
}
pub fn cross(a: &V3, b: &V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub fn dot(a: &V3, b: &V3) -> f64 {
    (0..3).map(|i| a[i] * b[i]).sum()
}
pub fn norm(v: &V3) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}
