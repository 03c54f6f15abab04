//! A dense square system of an elimination onto the outputs, emitted as its own function:
//! forward kinematics' reduced system `A z = r` (one row per actuator) and inverse dynamics'
//! `A U = rhs` (one column per actuator). Gaussian elimination over `A`'s structural non-zeros
//! in the pivot order chosen at the home (`block::eliminate`, checked at run time by the
//! threshold test that declines like the inverse-kinematics blocks do), the solve, and the
//! inverse column by column through the factors, whose exact `‖A⁻¹‖₁` the condition numbers
//! need; orders up to 3 by the adjugate (`block::factor_norms`).
//!
//! Replaces the runtime's general `linalg::invert_fixed` (partial pivoting at run time, loops
//! over run-time indices): 2 070 instructions for the 6-UPS's 6 × 6 (1 080 emitted), 13 400 for
//! the two-stage robot's 12 × 12 (5 600). A rigorous bound from the factors' comparison
//! matrices (`‖M(U)⁻¹‖₁ ‖M(L)⁻¹‖₁`, `n²` operations) was tried and ran 14 000 times above the
//! exact value on the two-stage robot, so the inverse stays.

use proc_macro2::{Ident, Literal, TokenStream};
use quote::quote;

use super::block::{Factor, eliminate, factor_norms, solve};
use super::tape::{Flops, Tape, V};

/// The function `name(a, r, z, inv) -> Option<f64>` solving `A z = r` for `A` given
/// column-major (`a[o][q]`: column `o`, row `q`) with the structural non-zeros `nonzero[o][q]`
/// and the values `home[o][q]` at the home; it writes `inv[q][o] = (A⁻¹)_{oq}` (column-major
/// like `a`) if `write_inv` and returns `‖A⁻¹‖₁`. `None` (at generation) when `A` is structurally singular;
/// the emitted function returns `None` where a pivot fails its threshold test or is zero.
pub fn square_solve(
    name: &Ident,
    nonzero: &[Vec<bool>],
    home: &[Vec<f64>],
    write_inv: bool,
) -> Option<(TokenStream, Flops)> {
    let n = nonzero.len();
    let mut t = Tape::default();
    // k[q][o]: row q, column o.
    let k: Vec<Vec<V>> = (0..n)
        .map(|q| {
            (0..n)
                .map(|o| {
                    if nonzero[o][q] {
                        t.push(quote!(a[#o][#q]), home[o][q])
                    } else {
                        V::Zero
                    }
                })
                .collect()
        })
        .collect();
    let r: Vec<V> = (0..n).map(|q| t.push(quote!(r[#q]), 0.0)).collect();
    let norm = if n <= 3 {
        // The adjugate, as `linalg::invert_fixed` at these orders, with its exact norm.
        let (f, _, norm) = factor_norms(&mut t, &k, 0)?;
        let Factor::Inverse(inv) = &f else {
            unreachable!("orders up to 3 are inverted")
        };
        for (o, row) in inv.iter().enumerate().filter(|_| write_inv) {
            for (q, &v) in row.iter().enumerate() {
                let tv = Tape::tok(v);
                t.stmt(quote!(inv[#q][#o] = #tv;));
            }
        }
        let z = solve(&mut t, &f, &r);
        store_z(&mut t, &z);
        norm
    } else {
        let f = eliminate(&mut t, &k)?;
        let z = solve(&mut t, &f, &r);
        store_z(&mut t, &z);
        // The inverse, column by column through the factors (a unit right-hand side folds its
        // zeros away), and its largest column sum.
        let sums: Vec<V> = (0..n)
            .map(|q| {
                let e: Vec<V> = (0..n)
                    .map(|j| if j == q { V::One } else { V::Zero })
                    .collect();
                let x = solve(&mut t, &f, &e);
                for (o, &v) in x.iter().enumerate().filter(|_| write_inv) {
                    let tv = Tape::tok(v);
                    t.stmt(quote!(inv[#q][#o] = #tv;));
                }
                t.sum_abs(&x)
            })
            .collect();
        t.max(&sums)
    };
    let tn = Tape::tok(norm);
    t.stmt(quote!(Some(#tn)));
    let flops = t.flops;
    let body = t.into_tokens();
    let n_lit = Literal::usize_unsuffixed(n);
    let item = quote! {
        /// The reduced system `A z = r` of the elimination onto the outputs (`a`, `inv`
        /// column-major): elimination in the pivot order chosen at the home, declining where a
        /// pivot fails its threshold test; writes `A⁻¹` and returns `‖A⁻¹‖₁`.
        #[inline(never)]
        #[allow(
            clippy::neg_multiply,
            clippy::neg_cmp_op_on_partial_ord,
            clippy::let_and_return,
            unused_variables
        )]
        fn #name(
            a: &[[f64; #n_lit]; #n_lit],
            r: &[f64; #n_lit],
            z: &mut [f64; #n_lit],
            inv: &mut [[f64; #n_lit]; #n_lit],
        ) -> Option<f64> {
            #body
        }
    };
    Some((item, flops))
}

/// `z[o] = x[o]`.
fn store_z(t: &mut Tape, x: &[V]) {
    for (o, &v) in x.iter().enumerate() {
        let tv = Tape::tok(v);
        t.stmt(quote!(z[#o] = #tv;));
    }
}
