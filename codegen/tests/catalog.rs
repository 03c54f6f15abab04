//! The catalogue of kernels and tasks (`rbss_codegen::catalog`) against the hand-written code
//! that spells it, read with `syn`:
//!
//! - the runtime's traits (`runtime/src/kernels.rs`, `runtime/src/tasks.rs`): each has exactly
//!   the methods the catalogue gives it, with the same argument and return types; the traits of
//!   the tasks require (with their supertraits) only kernels of their task, and each kernel of a
//!   task is offered by one of those traits;
//! - the robots that wrap a generated one (the `rbss` command's counting robot in
//!   `src/solver_table.rs`, the tests' `NoSolve` and `Chords`): each forwards every method of
//!   `Kernels` and `Dynamics` but those it hides on purpose, listed here; the counting robot's
//!   counter of each method is the kernel of that name.
//!
//! A kernel added to the catalogue and not to the runtime's trait (or the other way round), or
//! not forwarded by a wrapper, fails here with the method's name.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use quote::ToTokens;
use rbss_codegen::catalog::{self, KERNELS, Method, Task, Trait};

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

fn parse_file(rel: &str) -> syn::File {
    let text = std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"));
    syn::parse_file(&text).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// A type as compact text, without the paths that differ between the runtime and a generated
/// crate (`rbss_runtime::`, `crate::kernels::`).
fn norm(tokens: impl ToTokens) -> String {
    tokens
        .to_token_stream()
        .to_string()
        .chars()
        .filter(|c| !c.is_whitespace())
        .collect::<String>()
        .replace("rbss_runtime::", "")
        .replace("crate::kernels::", "")
}

/// A signature: the argument types after `&self` and the return type (`()` as "").
type Sig = (Vec<String>, String);

fn sig_of(f: &syn::Signature) -> Sig {
    let args = f
        .inputs
        .iter()
        .filter_map(|a| match a {
            syn::FnArg::Typed(t) => Some(norm(&t.ty)),
            syn::FnArg::Receiver(_) => None,
        })
        .collect();
    let ret = match &f.output {
        syn::ReturnType::Default => String::new(),
        syn::ReturnType::Type(_, t) => norm(t),
    };
    (args, ret)
}

fn catalogue_sig(m: &Method) -> Sig {
    let ty =
        |s: &str| norm(syn::parse_str::<syn::Type>(s).unwrap_or_else(|e| panic!("`{s}`: {e}")));
    let ret = if m.ret.is_empty() {
        String::new()
    } else {
        ty(m.ret)
    };
    (m.args.iter().map(|(_, t)| ty(t)).collect(), ret)
}

/// The methods the catalogue gives a trait: its head and the forwarding of its kernels.
fn catalogue_methods(t: Trait) -> BTreeMap<&'static str, Sig> {
    KERNELS
        .iter()
        .filter(|k| k.full == Some(t) || k.scene == Some(t))
        .flat_map(|k| k.methods)
        .chain(t.head())
        .map(|m| (m.name, catalogue_sig(m)))
        .collect()
}

/// A trait of a runtime file: its methods (signature, and whether it has a default body) and
/// the names of its supertraits.
struct RuntimeTrait {
    methods: BTreeMap<String, (Sig, bool)>,
    supertraits: Vec<String>,
}

fn runtime_trait(t: Trait) -> RuntimeTrait {
    let file = parse_file(t.source());
    let item = file
        .items
        .iter()
        .find_map(|i| match i {
            syn::Item::Trait(tr) if tr.ident == t.name() => Some(tr),
            _ => None,
        })
        .unwrap_or_else(|| panic!("no trait `{}` in {}", t.name(), t.source()));
    let methods = item
        .items
        .iter()
        .filter_map(|i| match i {
            syn::TraitItem::Fn(f) => Some((
                f.sig.ident.to_string(),
                (sig_of(&f.sig), f.default.is_some()),
            )),
            _ => None,
        })
        .collect();
    let supertraits = item
        .supertraits
        .iter()
        .filter_map(|b| match b {
            syn::TypeParamBound::Trait(tb) => tb.path.segments.last().map(|s| s.ident.to_string()),
            _ => None,
        })
        .collect();
    RuntimeTrait {
        methods,
        supertraits,
    }
}

fn trait_named(name: &str) -> Trait {
    Trait::all()
        .into_iter()
        .find(|t| t.name() == name)
        .unwrap_or_else(|| panic!("the runtime's trait `{name}` is not in the catalogue"))
}

#[test]
fn runtime_traits_have_the_catalogues_methods() {
    let mut bad = Vec::new();
    for t in Trait::all() {
        let want = catalogue_methods(t);
        let got = runtime_trait(t).methods;
        for (name, sig) in &want {
            match got.get(*name) {
                None => bad.push(format!(
                    "{}: `{}` has no method `{name}` (the catalogue's)",
                    t.source(),
                    t.name()
                )),
                Some((s, _)) if s != sig => bad.push(format!(
                    "{}: `{}::{name}` is {s:?}, the catalogue's {sig:?}",
                    t.source(),
                    t.name()
                )),
                Some(_) => {}
            }
        }
        for name in got.keys() {
            if !want.contains_key(name.as_str()) {
                bad.push(format!(
                    "{}: `{}::{name}` is not in the catalogue (codegen/src/catalog.rs)",
                    t.source(),
                    t.name()
                ));
            }
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

/// The trait of a task with its supertraits, transitively.
fn with_supertraits(name: &str, out: &mut BTreeSet<String>) {
    if out.insert(name.to_string()) {
        for s in runtime_trait(trait_named(name)).supertraits {
            with_supertraits(&s, out);
        }
    }
}

/// The kernels a task's solvers may call: its own and those of the tasks it implies.
fn task_kernels(t: Task, out: &mut BTreeSet<&'static str>) {
    out.extend(t.kernels());
    for &i in t.implies() {
        task_kernels(i, out);
    }
}

#[test]
fn task_traits_need_exactly_the_tasks_kernels() {
    let kernel_of = |method: &str, t: Trait| {
        KERNELS
            .iter()
            .find(|k| k.scene == Some(t) && k.methods.iter().any(|m| m.name == method))
            .map(|k| k.name)
    };
    let mut bad = Vec::new();
    for task in Task::ALL {
        let mut traits = BTreeSet::new();
        with_supertraits(task.trait_name(), &mut traits);
        let mut kernels = BTreeSet::new();
        task_kernels(task, &mut kernels);
        // Every method a scene crate must write for the task is one of its kernels.
        for tr in &traits {
            let t = trait_named(tr);
            for (method, (_, default)) in runtime_trait(t).methods {
                if default || t.head().iter().any(|m| m.name == method) {
                    continue;
                }
                match kernel_of(&method, t) {
                    Some(k) if kernels.contains(k) => {}
                    k => bad.push(format!(
                        "task `{}`: its trait needs `{tr}::{method}` (kernel {k:?}), not among its kernels {kernels:?}",
                        task.name()
                    )),
                }
            }
        }
        // Every kernel of the task is offered by its trait or a supertrait.
        for k in &kernels {
            let kernel = catalog::kernel(k).expect("a task's kernel is in the catalogue");
            match kernel.scene {
                Some(t) if traits.contains(t.name()) => {}
                t => bad.push(format!(
                    "task `{}`: kernel `{k}` is offered by {t:?}, not by its traits {traits:?}",
                    task.name()
                )),
            }
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

/// The table of tasks in the docs of `runtime/src/tasks.rs` names each task's trait and
/// kernels (or the tasks whose kernels it takes) as the catalogue does.
#[test]
fn the_runtimes_table_of_tasks_is_the_catalogues() {
    let text = std::fs::read_to_string(root().join("runtime/src/tasks.rs")).unwrap();
    let ticked = |cell: &str| -> Vec<String> {
        cell.split('`')
            .skip(1)
            .step_by(2)
            .map(str::to_string)
            .collect()
    };
    let mut rows = 0;
    for line in text.lines().filter_map(|l| l.strip_prefix("//! | `")) {
        let cells: Vec<&str> = line.split(" | ").collect();
        let name = cells[0].split('`').next().unwrap();
        let task = Task::from_name(name).unwrap_or_else(|| panic!("no task `{name}`: {line}"));
        assert_eq!(ticked(cells[1]), [task.trait_name()], "{line}");
        let want: Vec<String> = if cells[2].starts_with("those of ") {
            task.implies()
                .iter()
                .map(|t| t.name().to_string())
                .collect()
        } else {
            task.kernels().iter().map(|k| k.to_string()).collect()
        };
        assert_eq!(ticked(cells[2]), want, "{line}");
        rows += 1;
    }
    assert_eq!(rows, Task::ALL.len(), "a row per task");
}

/// The methods of `impl TRAIT<N, M> for WRAPPER<K>` in `file`.
fn wrapper_methods(file: &syn::File, tr: &str, wrapper: &str) -> BTreeMap<String, syn::ImplItemFn> {
    let imp =
        file.items
            .iter()
            .find_map(|i| match i {
                syn::Item::Impl(imp)
                    if imp.trait_.as_ref().is_some_and(|(_, p, _)| {
                        p.segments.last().is_some_and(|s| s.ident == tr)
                    }) && norm(&imp.self_ty).starts_with(&format!("{wrapper}<")) =>
                {
                    Some(imp)
                }
                _ => None,
            })
            .unwrap_or_else(|| panic!("no `impl {tr} for {wrapper}`"));
    imp.items
        .iter()
        .filter_map(|i| match i {
            syn::ImplItem::Fn(f) => Some((f.sig.ident.to_string(), f.clone())),
            _ => None,
        })
        .collect()
}

#[test]
fn wrapping_robots_forward_every_method_they_do_not_hide() {
    // (file, wrapper, trait, the methods it hides on purpose)
    let wrappers: [(&str, &str, &str, &[&str]); 7] = [
        (
            "src/solver_table.rs",
            "Counting",
            "Kernels",
            // Left to the defaults (no closure checks): see the report of this change.
            &["closure_checks", "closure_check"],
        ),
        ("src/solver_table.rs", "Counting", "Dynamics", &[]),
        (
            "src/solver_table.rs",
            "Counting",
            "DynamicsDerivatives",
            &[],
        ),
        (
            "tests/generated_solves.rs",
            "NoSolve",
            "Kernels",
            &[
                "ik_block_solve",
                "forward_rates_solve",
                "forward_rates_keep",
                "forward_rates_chord",
                "closure_checks",
                "closure_check",
                "constraints_jacobian_ik",
                "constraints_jacobian_p",
            ],
        ),
        (
            "tests/generated_solves.rs",
            "NoSolve",
            "Dynamics",
            &["forward_dynamics_solve", "inverse_dynamics_solve"],
        ),
        (
            "tests/generated_kinematics.rs",
            "NoSolve",
            "Kernels",
            &[
                "ik_block_solve",
                "forward_rates_solve",
                "forward_rates_keep",
                "forward_rates_chord",
                "constraints_jacobian_ik",
                "constraints_jacobian_p",
            ],
        ),
        ("tests/generated_kinematics.rs", "Chords", "Kernels", &[]),
    ];
    let mut bad = Vec::new();
    for (file, wrapper, tr, hides) in wrappers {
        let t = trait_named(tr);
        let want = catalogue_methods(t);
        let got = wrapper_methods(&parse_file(file), tr, wrapper);
        let missing: BTreeSet<&str> = want
            .keys()
            .copied()
            .filter(|m| !got.contains_key(*m))
            .collect();
        let hides: BTreeSet<&str> = hides.iter().copied().collect();
        if missing != hides {
            bad.push(format!(
                "{file}: `{wrapper}` leaves {missing:?} of `{tr}` to the defaults; it is known to hide {hides:?}"
            ));
        }
        for (m, f) in &got {
            match want.get(m.as_str()) {
                None => bad.push(format!(
                    "{file}: `{wrapper}::{m}` is not a method of `{tr}`"
                )),
                Some(sig) if *sig != sig_of(&f.sig) => bad.push(format!(
                    "{file}: `{wrapper}::{m}` is {:?}, the catalogue's {sig:?}",
                    sig_of(&f.sig)
                )),
                Some(_) => {}
            }
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

/// A full robot (`Kernels`, `Dynamics`) offers every task through the blanket impls of
/// `runtime/src/tasks.rs`: each forwards every method of its trait, none left to a default.
#[test]
fn blanket_impls_forward_every_method() {
    let file = parse_file("runtime/src/tasks.rs");
    let mut bad = Vec::new();
    let mut seen = 0;
    for item in &file.items {
        let syn::Item::Impl(imp) = item else { continue };
        let Some((_, path, _)) = &imp.trait_ else {
            continue;
        };
        if norm(&imp.self_ty) != "T" {
            continue;
        }
        let tr = path.segments.last().unwrap().ident.to_string();
        let want = catalogue_methods(trait_named(&tr));
        let got: BTreeSet<String> = imp
            .items
            .iter()
            .filter_map(|i| match i {
                syn::ImplItem::Fn(f) => Some(f.sig.ident.to_string()),
                _ => None,
            })
            .collect();
        let want: BTreeSet<String> = want.keys().map(|k| k.to_string()).collect();
        if got != want {
            bad.push(format!(
                "runtime/src/tasks.rs: the blanket `impl {tr} for T` has {got:?}, the catalogue {want:?}"
            ));
        }
        seen += 1;
    }
    assert_eq!(
        seen,
        Task::ALL.len() + 4,
        "a blanket impl per trait of `tasks`"
    );
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

/// `rbss bench solvers` counts each kernel call in `Counting`: `self.hit(i)` in the method
/// `NAME` must count `KERNELS[i] == NAME`, and every kernel it counts is the catalogue's.
#[test]
fn the_solver_tables_counters_name_catalogue_kernels() {
    let file = parse_file("src/solver_table.rs");
    let names: Vec<String> = file
        .items
        .iter()
        .find_map(|i| match i {
            syn::Item::Const(c) if c.ident == "KERNELS" => Some(&c.expr),
            _ => None,
        })
        .and_then(|e| match &**e {
            syn::Expr::Array(a) => Some(
                a.elems
                    .iter()
                    .filter_map(|e| match e {
                        syn::Expr::Lit(syn::ExprLit {
                            lit: syn::Lit::Str(s),
                            ..
                        }) => Some(s.value()),
                        _ => None,
                    })
                    .collect(),
            ),
            _ => None,
        })
        .expect("src/solver_table.rs: `const KERNELS: [&str; _] = [...]`");
    for n in &names {
        let k = catalog::kernel(n).unwrap_or_else(|| panic!("`{n}` is not in the catalogue"));
        assert!(!k.solve, "`{n}` is a solve, not a kernel");
    }
    let mut counted = 0;
    for tr in ["Kernels", "Dynamics", "DynamicsDerivatives"] {
        for (m, f) in wrapper_methods(&file, tr, "Counting") {
            let body = norm(&f.block);
            let Some(i) = body
                .split("self.hit(")
                .nth(1)
                .and_then(|r| r.split(')').next())
                .and_then(|i| i.parse::<usize>().ok())
            else {
                continue;
            };
            assert_eq!(names.get(i), Some(&m), "`Counting::{m}` counts `hit({i})`");
            counted += 1;
        }
    }
    assert_eq!(
        counted,
        names.len(),
        "every entry of KERNELS is counted once"
    );
}

/// `rbss-codegen --no-derivatives` (the plain library of `rbss --model-file`): the full crate
/// of a model without the derivative kernel and the `impl` of its trait, and nothing else
/// missing: every other kernel and `impl` is the full crate's, character for character.
#[test]
fn a_crate_without_derivatives_lacks_the_derivative_kernel_only() {
    let path = root().join("models/five_bar.toml");
    let source = std::fs::read_to_string(&path).unwrap();
    let module = |no_derivatives: bool| {
        let opts = rbss_codegen::Options {
            no_derivatives,
            ..Default::default()
        };
        let g = rbss_codegen::generate("models/five_bar.toml", &source, &opts, &mut |_| {})
            .unwrap_or_else(|e| panic!("{e}"));
        let (_, text) = g
            .files
            .into_iter()
            .find(|(p, _)| p.ends_with("src/five_bar.rs"))
            .expect("the module");
        syn::parse_file(&text).unwrap()
    };
    // Items by a name: functions by theirs, `impl`s by their trait's.
    let items = |f: &syn::File| -> BTreeMap<String, String> {
        f.items
            .iter()
            .filter_map(|i| match i {
                syn::Item::Fn(f) => Some((format!("fn {}", f.sig.ident), norm(f))),
                syn::Item::Impl(imp) => imp.trait_.as_ref().map(|(_, p, _)| {
                    let name = p.segments.last().unwrap().ident.to_string();
                    (format!("impl {name}"), norm(imp))
                }),
                _ => None,
            })
            .collect()
    };
    let (full, lean) = (items(&module(false)), items(&module(true)));
    let gone: Vec<&String> = full.keys().filter(|k| !lean.contains_key(*k)).collect();
    assert_eq!(
        gone,
        ["fn dynamics_derivatives", "impl DynamicsDerivatives"],
        "what --no-derivatives leaves out"
    );
    assert!(lean.keys().all(|k| full.contains_key(k)));
    for (k, v) in &lean {
        assert_eq!(v, &full[k], "`{k}` differs without the derivatives");
    }
    assert!(lean.contains_key("impl Dynamics") && lean.contains_key("fn dynamics_terms"));
}
