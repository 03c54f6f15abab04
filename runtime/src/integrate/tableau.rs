//! The adaptive embedded Runge–Kutta pairs' tableaux (Hairer, Nørsett & Wanner, *Solving
//! ODEs I*, II.4-5 and II.10; codes `DOPRI5` and `DOP853`).
//!
//! Both pairs have the same shape: stages `0..S` at `t + c_s h`, the solution
//! `y + h Σ b_j k_j` (row `S` of the tableau), and its derivative as stage `S`, which is the next
//! step's stage 0 (FSAL). DOPRI5's error estimate uses stage `S`, so it is evaluated before the
//! estimate; DOP853's does not, so it is evaluated only once the step is accepted
//! (`simulator.rs`).

// DOP853's coefficients as Hairer's `dop853.f` publishes them (30 digits): the compiler rounds
// each to the nearest `f64`, so nothing is lost by keeping them as published.
#![allow(clippy::excessive_precision)]

/// Stage slots of the simulator: DOP853's 12 stages and the FSAL one.
pub(super) const STAGES: usize = 13;

/// An embedded pair.
pub(super) struct Pair {
    /// `S`: the index of the solution's row in `a` and of the FSAL stage.
    pub(super) solution: usize,
    /// Stage times `c_s` (`c_S = 1`).
    pub(super) c: &'static [f64],
    /// Row `s` of the tableau (`s` coefficients) for `s = 1..=S`; row `S` is `b`.
    pub(super) a: &'static [&'static [f64]],
    /// The error weights on the stages `0..=S` (DOP853: of its fifth-order estimate).
    pub(super) e: &'static [f64],
    /// DOP853's third-order error weights (empty for DOPRI5).
    pub(super) e3: &'static [f64],
    /// The step-size exponent `1 / (q + 1)`, `q` the order of the error estimate's method.
    pub(super) expo: f64,
    /// The PI controller's weight on `beta` in the exponent (Hairer: 0.75 for DOPRI5, 0.2 for
    /// DOP853).
    pub(super) pi_weight: f64,
    /// `h_new / h` within `[fac_min, fac_max]` (Hairer's `FAC1`, `FAC2`).
    pub(super) fac_min: f64,
    pub(super) fac_max: f64,
}

/// The safety factor of the step-size controller.
pub(super) const SAFE: f64 = 0.9;

/// Dormand–Prince 5(4) (Hairer's `DOPRI5`).
pub(super) const DOPRI5: Pair = Pair {
    solution: 6,
    c: &[0.0, 0.2, 0.3, 0.8, 8.0 / 9.0, 1.0, 1.0],
    a: &[
        &[],
        &[0.2],
        &[3.0 / 40.0, 9.0 / 40.0],
        &[44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0],
        &[
            19372.0 / 6561.0,
            -25360.0 / 2187.0,
            64448.0 / 6561.0,
            -212.0 / 729.0,
        ],
        &[
            9017.0 / 3168.0,
            -355.0 / 33.0,
            46732.0 / 5247.0,
            49.0 / 176.0,
            -5103.0 / 18656.0,
        ],
        &[
            35.0 / 384.0,
            0.0,
            500.0 / 1113.0,
            125.0 / 192.0,
            -2187.0 / 6784.0,
            11.0 / 84.0,
        ],
    ],
    e: &[
        71.0 / 57600.0,
        0.0,
        -71.0 / 16695.0,
        71.0 / 1920.0,
        -17253.0 / 339200.0,
        22.0 / 525.0,
        -1.0 / 40.0,
    ],
    e3: &[],
    expo: 0.2,
    pi_weight: 0.75,
    fac_min: 0.2,
    fac_max: 10.0,
};

/// `b` of DOP853 (row 12 of its tableau), also the base of its third-order weights.
const DOP853_B: [f64; 12] = [
    5.42937341165687622380535766363e-2,
    0.0,
    0.0,
    0.0,
    0.0,
    4.45031289275240888144113950566,
    1.89151789931450038304281599044,
    -5.8012039600105847814672114227,
    3.1116436695781989440891606237e-1,
    -1.52160949662516078556178806805e-1,
    2.01365400804030348374776537501e-1,
    4.47106157277725905176885569043e-2,
];

/// Dormand–Prince 8(5,3) (Hairer's `DOP853`; the coefficients of its `dop853.f`).
pub(super) const DOP853: Pair = Pair {
    solution: 12,
    c: &[
        0.0,
        0.526001519587677318785587544488e-1,
        0.789002279381515978178381316732e-1,
        0.118350341907227396726757197510,
        0.281649658092772603273242802490,
        0.333333333333333333333333333333,
        0.25,
        0.307692307692307692307692307692,
        0.651282051282051282051282051282,
        0.6,
        0.857142857142857142857142857142,
        1.0,
        1.0,
    ],
    a: &[
        &[],
        &[5.26001519587677318785587544488e-2],
        &[
            1.97250569845378994544595329183e-2,
            5.91751709536136983633785987549e-2,
        ],
        &[
            2.95875854768068491816892993775e-2,
            0.0,
            8.87627564304205475450678981324e-2,
        ],
        &[
            2.41365134159266685502369798665e-1,
            0.0,
            -8.84549479328286085344864962717e-1,
            9.24834003261792003115737966543e-1,
        ],
        &[
            3.7037037037037037037037037037e-2,
            0.0,
            0.0,
            1.70828608729473871279604482173e-1,
            1.25467687566822425016691814123e-1,
        ],
        &[
            3.7109375e-2,
            0.0,
            0.0,
            1.70252211019544039314978060272e-1,
            6.02165389804559606850219397283e-2,
            -1.7578125e-2,
        ],
        &[
            3.70920001185047927108779319836e-2,
            0.0,
            0.0,
            1.70383925712239993810214054705e-1,
            1.07262030446373284651809199168e-1,
            -1.53194377486244017527936158236e-2,
            8.27378916381402288758473766002e-3,
        ],
        &[
            6.24110958716075717114429577812e-1,
            0.0,
            0.0,
            -3.36089262944694129406857109825,
            -8.68219346841726006818189891453e-1,
            2.75920996994467083049415600797e1,
            2.01540675504778934086186788979e1,
            -4.34898841810699588477366255144e1,
        ],
        &[
            4.77662536438264365890433908527e-1,
            0.0,
            0.0,
            -2.48811461997166764192642586468,
            -5.90290826836842996371446475743e-1,
            2.12300514481811942347288949897e1,
            1.52792336328824235832596922938e1,
            -3.32882109689848629194453265587e1,
            -2.03312017085086261358222928593e-2,
        ],
        &[
            -9.3714243008598732571704021658e-1,
            0.0,
            0.0,
            5.18637242884406370830023853209,
            1.09143734899672957818500254654,
            -8.14978701074692612513997267357,
            -1.85200656599969598641566180701e1,
            2.27394870993505042818970056734e1,
            2.49360555267965238987089396762,
            -3.0467644718982195003823669022,
        ],
        &[
            2.27331014751653820792359768449,
            0.0,
            0.0,
            -1.05344954667372501984066689879e1,
            -2.00087205822486249909675718444,
            -1.79589318631187989172765950534e1,
            2.79488845294199600508499808837e1,
            -2.85899827713502369474065508674,
            -8.87285693353062954433549289258,
            1.23605671757943030647266201528e1,
            6.43392746015763530355970484046e-1,
        ],
        &DOP853_B,
    ],
    e: &[
        0.1312004499419488073250102996e-1,
        0.0,
        0.0,
        0.0,
        0.0,
        -0.1225156446376204440720569753e1,
        -0.4957589496572501915214079952,
        0.1664377182454986536961530415e1,
        -0.3503288487499736816886487290,
        0.3341791187130174790297318841,
        0.8192320648511571246570742613e-1,
        -0.2235530786388629525884427845e-1,
        0.0,
    ],
    // b minus the third-order weights (Hairer's BHH1, BHH2, BHH3 on stages 0, 8, 11).
    e3: &[
        DOP853_B[0] - 0.244094488188976377952755905512,
        0.0,
        0.0,
        0.0,
        0.0,
        DOP853_B[5],
        DOP853_B[6],
        DOP853_B[7],
        DOP853_B[8] - 0.733846688281611857341361741547,
        DOP853_B[9],
        DOP853_B[10],
        DOP853_B[11] - 0.220588235294117647058823529412e-1,
        0.0,
    ],
    expo: 0.125,
    pi_weight: 0.2,
    fac_min: 1.0 / 3.0,
    fac_max: 6.0,
};

#[cfg(test)]
mod tests {
    use super::*;

    /// The conditions a typo in a coefficient breaks: every row of the tableau sums to its
    /// stage time (`Σ_j a_sj = c_s`), the weights integrate `t^(k-1)` exactly up to the pair's
    /// order (`Σ b_j c_j^(k-1) = 1/k`, k = 1..=p) and `Σ_j b_j a_jl c_l^(k-2) = 1/(k(k-1))`
    /// likewise, and the error weights vanish on constants (`Σ e_j = 0`).
    fn check(pair: &Pair, order: i32) {
        let s_end = pair.solution;
        for s in 1..=s_end {
            let sum: f64 = pair.a[s].iter().sum();
            assert!(
                (sum - pair.c[s]).abs() < 1e-14,
                "row {s}: {sum} != {}",
                pair.c[s]
            );
        }
        let b = pair.a[s_end];
        for k in 1..=order {
            let q: f64 = b.iter().zip(pair.c).map(|(b, c)| b * c.powi(k - 1)).sum();
            assert!((q - 1.0 / f64::from(k)).abs() < 1e-14, "k = {k}: {q}");
        }
        for k in 2..=order {
            let mut q = 0.0;
            for (j, bj) in b.iter().enumerate() {
                for (l, a) in pair.a[j].iter().enumerate() {
                    q += bj * a * pair.c[l].powi(k - 2);
                }
            }
            let want = 1.0 / f64::from(k * (k - 1));
            assert!((q - want).abs() < 1e-13, "k = {k}: {q} != {want}");
        }
        for e in [pair.e, pair.e3] {
            let sum: f64 = e.iter().sum();
            assert!(sum.abs() < 1e-14, "error weights sum to {sum}");
        }
    }

    #[test]
    fn dopri5_tableau_has_order_5() {
        check(&DOPRI5, 5);
    }

    #[test]
    fn dop853_tableau_has_order_8() {
        check(&DOP853, 8);
    }
}
