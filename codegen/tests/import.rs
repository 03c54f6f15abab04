//! Importing URDF, MJCF and SDF (and the model file that names a source): the imported robots derive the same
//! kernels as the same robots written in TOML, at random states; the generated header records
//! the source's hash, so a changed source makes the crate stale; every importer error has a
//! golden file (`codegen/tests/import/ui/*`, `RBSS_BLESS=1` rewrites them).

use std::path::{Path, PathBuf};

use rbss_codegen::derive::{Derivation, derive};
use rbss_codegen::graph::Id;
use rbss_codegen::model::Model;
use rbss_codegen::parse::{parse_model, parse_model_file};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The `<inertial>` of the SDF tests' links written in the tests: 1 kg, 0.01 kg m² about each axis.
const UNIT_INERTIAL: &str = "<inertial><mass>1</mass><inertia><ixx>0.01</ixx><iyy>0.01</iyy>\
                             <izz>0.01</izz></inertia></inertial>";

fn here() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/import")
}

fn model_at(path: &Path) -> Model {
    parse_model_file(path).unwrap_or_else(|e| panic!("{}", e.render()))
}

fn derived(m: &Model) -> Derivation {
    derive(m, true, &vec![false; m.parameters.len()], &mut |_| {})
        .unwrap_or_else(|e| panic!("{e:?}"))
}

/// f, G, gamma, M, psi at a state.
fn kernels(d: &Derivation, p: &[f64], x: &[f64], v: &[f64]) -> Vec<f64> {
    let vals = d.graph.eval_all(x, v, p);
    let dy = d.dynamics.as_ref().unwrap();
    let ids: Vec<Id> =
        d.f.iter()
            .chain(d.g.iter().flatten())
            .chain(&d.gamma)
            .chain(dy.mass.iter().flatten())
            .chain(&dy.psi)
            .copied()
            .collect();
    ids.iter().map(|&i| vals[i as usize]).collect()
}

/// A deterministic pseudo-random sequence in [-1, 1) (xorshift).
fn random(seed: &mut u64) -> f64 {
    *seed ^= *seed << 13;
    *seed ^= *seed >> 7;
    *seed ^= *seed << 17;
    (*seed >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// The largest difference `|a - b| / (1 + |a|)` of every kernel entry (f, G, gamma, M, psi) of
/// two models at 16 random states, each evaluated with its own parameters. The coordinates are
/// matched by name (an importer orders them as the source's tree does), the constraints by
/// position.
fn worst_difference(a: &Model, b: &Model) -> f64 {
    let names = |m: &Model| {
        m.coordinates
            .iter()
            .map(|c| c.name.clone())
            .collect::<Vec<_>>()
    };
    let (na, nb) = (names(a), names(b));
    let mut sorted = (na.clone(), nb.clone());
    sorted.0.sort();
    sorted.1.sort();
    assert_eq!(sorted.0, sorted.1, "the coordinates differ");
    // perm[j]: the index in `a` of b's coordinate j.
    let perm: Vec<usize> = nb
        .iter()
        .map(|n| na.iter().position(|m| m == n).unwrap())
        .collect();
    let by_name = |m: &Model, idx: &[usize]| {
        idx.iter()
            .map(|&i| m.coordinates[i].name.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(
        by_name(a, &a.actuated),
        by_name(b, &b.actuated),
        "the actuated coordinates differ"
    );
    assert_eq!(
        by_name(a, &a.outputs),
        by_name(b, &b.outputs),
        "the outputs differ"
    );
    let (da, db) = (derived(a), derived(b));
    assert_eq!(da.f.len(), db.f.len(), "the numbers of constraints differ");
    let pa: Vec<f64> = a.parameters.iter().map(|q| q.value).collect();
    let pb: Vec<f64> = b.parameters.iter().map(|q| q.value).collect();
    let n = na.len();
    let m = da.f.len();
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut worst = 0.0f64;
    for _ in 0..16 {
        let x: Vec<f64> = (0..n).map(|_| 3.0 * random(&mut seed)).collect();
        let v: Vec<f64> = (0..n).map(|_| 2.0 * random(&mut seed)).collect();
        let xb: Vec<f64> = perm.iter().map(|&i| x[i]).collect();
        let vb: Vec<f64> = perm.iter().map(|&i| v[i]).collect();
        let (ka, kb) = (kernels(&da, &pa, &x, &v), kernels(&db, &pb, &xb, &vb));
        // b's entries in a's order: f (m), G (m x n), gamma (m), M (n x n), psi (n).
        let mut inv = vec![0; n];
        for (j, &i) in perm.iter().enumerate() {
            inv[i] = j;
        }
        let mut kb_in_a = Vec::with_capacity(kb.len());
        kb_in_a.extend_from_slice(&kb[..m]);
        for r in 0..m {
            kb_in_a.extend((0..n).map(|c| kb[m + r * n + inv[c]]));
        }
        kb_in_a.extend_from_slice(&kb[m + m * n..m + m * n + m]);
        let at = 2 * m + m * n;
        for r in 0..n {
            kb_in_a.extend((0..n).map(|c| kb[at + inv[r] * n + inv[c]]));
        }
        kb_in_a.extend((0..n).map(|r| kb[at + n * n + inv[r]]));
        assert_eq!(ka.len(), kb_in_a.len(), "the kernels have different sizes");
        for (u, w) in ka.iter().zip(&kb_in_a) {
            worst = worst.max((u - w).abs() / (1.0 + u.abs()));
        }
    }
    worst
}

#[test]
fn ur5_from_urdf_has_the_kernels_of_models_ur5() {
    let plain = model_at(&root().join("models/ur5.toml"));
    let imported = model_at(&here().join("ur5.toml"));
    let worst = worst_difference(&plain, &imported);
    println!("UR5 from URDF vs models/ur5.toml: worst relative difference {worst:e}");
    // The URDF's angles are f64 (pi/2 as 1.5707963267948966): equal to rounding, not bits.
    assert!(worst < 1e-12, "worst {worst:e}");
    assert!(
        worst > 0.0,
        "bit-identical: the comparison compared nothing"
    );
}

#[test]
fn stewart_6ups_from_mjcf_has_the_kernels_of_models_stewart_6ups() {
    let plain = model_at(&root().join("models/stewart_6ups.toml"));
    let imported = model_at(&here().join("stewart_6ups.toml"));
    let worst = worst_difference(&plain, &imported);
    println!("6-UPS from MJCF vs models/stewart_6ups.toml: worst relative difference {worst:e}");
    assert!(worst < 1e-12, "worst {worst:e}");
    assert!(
        worst > 0.0,
        "bit-identical: the comparison compared nothing"
    );
}

#[test]
fn four_bar_from_mjcf_has_the_kernels_of_the_toml_four_bar() {
    let plain = model_at(&here().join("four_bar.toml"));
    let imported = model_at(&here().join("four_bar_mjcf.toml"));
    let worst = worst_difference(&plain, &imported);
    println!("four-bar from MJCF vs four_bar.toml: worst relative difference {worst:e}");
    assert!(worst < 1e-12, "worst {worst:e}");
    assert!(
        worst > 0.0,
        "bit-identical: the comparison compared nothing"
    );
}

#[test]
fn four_bar_from_sdf_has_the_kernels_of_the_toml_four_bar() {
    let plain = model_at(&here().join("four_bar.toml"));
    let imported = model_at(&here().join("four_bar_sdf.toml"));
    let worst = worst_difference(&plain, &imported);
    println!("four-bar from SDF vs four_bar.toml: worst relative difference {worst:e}");
    assert!(worst < 1e-12, "worst {worst:e}");
    assert!(
        worst > 0.0,
        "bit-identical: the comparison compared nothing"
    );
}

#[test]
fn mjcf_include_reads_the_included_bodies_and_hashes_them() {
    let plain = model_at(&here().join("four_bar.toml"));
    let split = model_at(&here().join("four_bar_split.toml"));
    let worst = worst_difference(&plain, &split);
    assert!(worst < 1e-12 && worst > 0.0, "worst {worst:e}");
    // The source's hash covers the included file: changing it changes the hash.
    use rbss_codegen::import::{Format, import_file};
    let dir = tempfile::tempdir().unwrap();
    for f in ["four_bar_split.xml", "four_bar_bodies.xml"] {
        std::fs::copy(here().join(f), dir.path().join(f)).unwrap();
    }
    let main = dir.path().join("four_bar_split.xml");
    let sha = || {
        let (m, _) = import_file(&main, "four_bar_split.xml", Format::Mjcf)
            .unwrap_or_else(|e| panic!("{}", e.render()));
        m.source.unwrap().sha256
    };
    let before = sha();
    let bodies = dir.path().join("four_bar_bodies.xml");
    let text = std::fs::read_to_string(&bodies).unwrap();
    std::fs::write(&bodies, text.replace("mass=\"2\"", "mass=\"2.5\"")).unwrap();
    assert_ne!(
        before,
        sha(),
        "a changed included file must change the source's hash"
    );
}

#[test]
fn mjcf_actuator_gear_is_the_coordinate_gear() {
    // The four-bar's motor with gear="50": the crank's `gear` (U in the motor's units), the
    // kernels unchanged (the gear scales U, not the equations).
    let dir = tempfile::tempdir().unwrap();
    let xml = std::fs::read_to_string(here().join("four_bar.xml")).unwrap();
    let geared = xml.replacen(
        "<motor joint=\"th1\" gear=\"1\"/>",
        "<motor joint=\"th1\" gear=\"50\"/>",
        1,
    );
    assert_ne!(geared, xml, "four_bar.xml's motor");
    std::fs::write(dir.path().join("four_bar.xml"), geared).unwrap();
    let overlay = std::fs::read_to_string(here().join("four_bar_mjcf.toml")).unwrap();
    std::fs::write(dir.path().join("four_bar_mjcf.toml"), overlay).unwrap();
    let m = model_at(&dir.path().join("four_bar_mjcf.toml"));
    let th1 = m.coordinates.iter().position(|c| c.name == "th1").unwrap();
    assert_eq!(m.actuated, vec![th1]);
    assert_eq!(m.coordinates[th1].gear, Some(50.0));
    let plain = model_at(&here().join("four_bar_mjcf.toml"));
    assert_eq!(plain.coordinates[th1].gear, None, "gear=\"1\" is no gear");
}

/// MJCF's joint `ref` (the joint's value at the body's pose as written, MuJoCo's `qpos0`): the
/// model with `ref` at `X` has the kernels of the same model without it at `X - ref`, and its
/// coordinates' homes are the `ref`s. On the four-bar (a hinge with `ref` in degrees inside a
/// `connect` loop, whose anchor is found at `qpos0`) and on an open chain with a slide and a
/// hinge about a general axis (the steps written out as expressions).
#[test]
fn mjcf_joint_ref_shifts_the_coordinate() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let overlay = "mjcf = \"SRC\"\n[robot]\nname = \"r\"\noutputs = [\"th3\"]\n\
                   [[loop]]\nname = \"pin\"\ncomponents = [\"x\", \"y\"]\n";
    let xml = std::fs::read_to_string(here().join("four_bar.xml")).unwrap();
    let with_ref = xml.replacen(
        "<joint name=\"th2\" axis=\"0 0 1\"/>",
        "<joint name=\"th2\" axis=\"0 0 1\" ref=\"20\"/>",
        1,
    );
    assert_ne!(with_ref, xml, "four_bar.xml's th2");
    std::fs::write(d.join("plain.xml"), &xml).unwrap();
    std::fs::write(d.join("ref.xml"), &with_ref).unwrap();
    std::fs::write(d.join("plain.toml"), overlay.replace("SRC", "plain.xml")).unwrap();
    std::fs::write(d.join("ref.toml"), overlay.replace("SRC", "ref.xml")).unwrap();
    let r20 = 20f64.to_radians();
    let shifted = model_at(&d.join("ref.toml"));
    let plain = model_at(&d.join("plain.toml"));
    let homes: Vec<f64> = shifted.coordinates.iter().map(|c| c.home).collect();
    assert!(
        (homes[1] - r20).abs() < 1e-15 && homes[0] == 0.0 && homes[2] == 0.0,
        "{homes:?}"
    );
    let worst = shifted_difference(&shifted, &plain, &[0.0, r20, 0.0]);
    assert!(worst < 1e-13, "four-bar with ref: {worst:e}");

    let chain = |refs: [&str; 2]| {
        format!(
            "<mujoco model=\"c\"><worldbody><body name=\"a\" pos=\"0.1 0 0\">\
             <joint name=\"s\" type=\"slide\" axis=\"0 -1 0\"{}/>\
             <inertial pos=\"0 0 0.1\" mass=\"2\" diaginertia=\"0.1 0.2 0.3\"/>\
             <body name=\"b\" pos=\"0 0.2 0\"><joint name=\"h\" axis=\"1 1 0\" pos=\"0 0 0.1\"{}/>\
             <inertial pos=\"0.1 0 0\" mass=\"1\" diaginertia=\"0.01 0.02 0.03\"/></body>\
             </body></worldbody></mujoco>",
            refs[0], refs[1]
        )
    };
    std::fs::write(d.join("c_plain.xml"), chain(["", ""])).unwrap();
    std::fs::write(
        d.join("c_ref.xml"),
        chain([" ref=\"0.15\"", " ref=\"-35\""]),
    )
    .unwrap();
    std::fs::write(d.join("c_plain.toml"), "mjcf = \"c_plain.xml\"\n").unwrap();
    std::fs::write(d.join("c_ref.toml"), "mjcf = \"c_ref.xml\"\n").unwrap();
    let shifted = model_at(&d.join("c_ref.toml"));
    let plain = model_at(&d.join("c_plain.toml"));
    let r35 = (-35f64).to_radians();
    let homes: Vec<f64> = shifted.coordinates.iter().map(|c| c.home).collect();
    assert!(
        (homes[0] - 0.15).abs() < 1e-15 && (homes[1] - r35).abs() < 1e-15,
        "{homes:?}"
    );
    let worst = shifted_difference(&shifted, &plain, &[0.15, r35]);
    assert!(worst < 1e-13, "chain with refs: {worst:e}");
}

/// URDF `planar` joints (were refused): three coordinates `NAME_x`, `NAME_y`, `NAME_theta`, not
/// actuated. With the axis z, the kernels of a cart-and-pole are those of the same robot written
/// by hand in TOML (`Tx Ty Rz` after the joint's origin); about a general axis `(1, 1, 0)/√2`, a
/// lone body (centre of mass at the joint, inertia `diag(0.1, 0.2, 0.3)`) has the mass matrix
/// `diag(m, m, aᵀ I a)` at every state: the two translations orthonormal and normal to the axis,
/// the rotation about it.
#[test]
fn urdf_planar_joints_are_three_coordinates() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let inertial = |m: f64, xyz: &str, i: [f64; 3]| {
        format!(
            "<inertial><origin xyz=\"{xyz}\"/><mass value=\"{m}\"/>\
             <inertia ixx=\"{}\" iyy=\"{}\" izz=\"{}\" ixy=\"0\" ixz=\"0\" iyz=\"0\"/></inertial>",
            i[0], i[1], i[2]
        )
    };
    std::fs::write(
        d.join("cart.urdf"),
        format!(
            "<robot name=\"cart\"><link name=\"ground\"/>\
             <link name=\"cart\">{}</link><link name=\"pole\">{}</link>\
             <joint name=\"base\" type=\"planar\"><origin xyz=\"0 0 0.5\"/><parent link=\"ground\"/>\
             <child link=\"cart\"/><axis xyz=\"0 0 1\"/></joint>\
             <joint name=\"hinge\" type=\"continuous\"><origin xyz=\"0.2 0 0\"/><parent link=\"cart\"/>\
             <child link=\"pole\"/><axis xyz=\"0 1 0\"/></joint></robot>",
            inertial(3.0, "0.05 0.02 0", [0.1, 0.2, 0.3]),
            inertial(0.5, "0 0 0.4", [0.02, 0.02, 0.001]),
        ),
    )
    .unwrap();
    std::fs::write(d.join("cart.toml"), "urdf = \"cart.urdf\"\n").unwrap();
    std::fs::write(
        d.join("cart_hand.toml"),
        "coordinates = [\n  { name = \"base_x\", unit = \"m\" },\n  { name = \"base_y\", unit = \"m\" },\n\
         { name = \"base_theta\", unit = \"rad\" },\n  { name = \"hinge\", unit = \"rad\" },\n]\n\
         [robot]\nname = \"cart_hand\"\ngravity = [0, 0, -9.81]\nactuated = [\"hinge\"]\n\
         [[body]]\nname = \"cart\"\ntransforms = [\"Tz(0.5)\", \"Tx(base_x)\", \"Ty(base_y)\", \"Rz(base_theta)\"]\n\
         mass = 3\ncom = [0.05, 0.02, 0]\ninertia = [0.1, 0.2, 0.3, 0, 0, 0]\n\
         [[body]]\nname = \"pole\"\nparent = \"cart\"\ntransforms = [\"Tx(0.2)\", \"Ry(hinge)\"]\n\
         mass = 0.5\ncom = [0, 0, 0.4]\ninertia = [0.02, 0.02, 0.001, 0, 0, 0]\n",
    )
    .unwrap();
    let imported = model_at(&d.join("cart.toml"));
    let names: Vec<&str> = imported
        .coordinates
        .iter()
        .map(|c| c.name.as_str())
        .collect();
    assert_eq!(names, ["base_x", "base_y", "base_theta", "hinge"]);
    let worst = worst_difference(&imported, &model_at(&d.join("cart_hand.toml")));
    assert!(worst < 1e-13, "planar cart vs its TOML: {worst:e}");

    std::fs::write(
        d.join("tilted.urdf"),
        format!(
            "<robot name=\"tilted\"><link name=\"ground\"/><link name=\"puck\">{}</link>\
             <joint name=\"p\" type=\"planar\"><origin xyz=\"0.1 0.2 0.3\" rpy=\"0.3 0 0\"/>\
             <parent link=\"ground\"/><child link=\"puck\"/><axis xyz=\"1 1 0\"/></joint></robot>",
            inertial(2.0, "0 0 0", [0.1, 0.2, 0.3]),
        ),
    )
    .unwrap();
    std::fs::write(d.join("tilted.toml"), "urdf = \"tilted.urdf\"\n").unwrap();
    let m = model_at(&d.join("tilted.toml"));
    let dv = derived(&m);
    let p: Vec<f64> = m.parameters.iter().map(|q| q.value).collect();
    let mut seed = 0x1234_5678_9abc_def0u64;
    let expected = [2.0, 2.0, 0.15];
    for _ in 0..8 {
        let x: Vec<f64> = (0..3).map(|_| 3.0 * random(&mut seed)).collect();
        let v: Vec<f64> = (0..3).map(|_| random(&mut seed)).collect();
        let k = kernels(&dv, &p, &x, &v);
        // No constraints: the kernels are M (3 x 3) then psi.
        for r in 0..3 {
            for c in 0..3 {
                let want = if r == c { expected[r] } else { 0.0 };
                assert!(
                    (k[r * 3 + c] - want).abs() < 1e-14,
                    "M[{r}][{c}] = {} at {x:?}, expected {want}",
                    k[r * 3 + c]
                );
            }
        }
    }
}

/// The largest difference `|a - b| / (1 + |a|)` of the kernels (f, G, gamma, M, psi) of `a` at
/// `X` and of `b` at `X - shift` (the same coordinates in the same order), at 16 random states.
fn shifted_difference(a: &Model, b: &Model, shift: &[f64]) -> f64 {
    let (da, db) = (derived(a), derived(b));
    let pa: Vec<f64> = a.parameters.iter().map(|q| q.value).collect();
    let pb: Vec<f64> = b.parameters.iter().map(|q| q.value).collect();
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut worst = 0.0f64;
    for _ in 0..16 {
        let x: Vec<f64> = shift.iter().map(|_| 3.0 * random(&mut seed)).collect();
        let v: Vec<f64> = shift.iter().map(|_| 2.0 * random(&mut seed)).collect();
        let xb: Vec<f64> = x.iter().zip(shift).map(|(x, s)| x - s).collect();
        let (ka, kb) = (kernels(&da, &pa, &x, &v), kernels(&db, &pb, &xb, &v));
        assert_eq!(ka.len(), kb.len());
        for (u, w) in ka.iter().zip(&kb) {
            worst = worst.max((u - w).abs() / (1.0 + u.abs()));
        }
    }
    worst
}

/// A copy of the UR5 model and its URDF in a temporary directory.
fn ur5_copy(dir: &Path, urdf: &str) -> String {
    let overlay = std::fs::read_to_string(here().join("ur5.toml")).unwrap();
    std::fs::write(dir.join("ur5.toml"), overlay).unwrap();
    std::fs::write(dir.join("ur5.urdf"), urdf).unwrap();
    dir.join("ur5.toml").display().to_string()
}

#[test]
fn the_header_records_the_source_and_a_changed_source_is_stale() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = std::fs::read_to_string(here().join("ur5.urdf")).unwrap();
    let path = ur5_copy(dir.path(), &urdf);
    let source = std::fs::read_to_string(&path).unwrap();
    let opts = rbss_codegen::Options::default();
    let a = rbss_codegen::generate(&path, &source, &opts, &mut |_| {}).unwrap();
    let module = |g: &rbss_codegen::Generated| {
        g.files
            .iter()
            .find(|(p, _)| p.ends_with("src/ur5_urdf.rs"))
            .unwrap()
            .1
            .clone()
    };
    let text = module(&a);
    let sha = {
        use sha2::Digest;
        let d = sha2::Sha256::digest(urdf.as_bytes());
        d.iter().map(|b| format!("{b:02x}")).collect::<String>()
    };
    let header: Vec<&str> = text.lines().take(5).collect();
    assert!(
        header
            .iter()
            .any(|l| l.starts_with("// source: ") && l.ends_with(&format!("sha256: {sha}"))),
        "header without the source's hash: {header:#?}"
    );
    // The model file unchanged, the URDF changed (one mass): the crate is stale.
    let changed = urdf.replacen("<mass value=\"8.393\"/>", "<mass value=\"8.4\"/>", 1);
    assert_ne!(changed, urdf);
    ur5_copy(dir.path(), &changed);
    let b = rbss_codegen::generate(&path, &source, &opts, &mut |_| {}).unwrap();
    let out = dir.path().join("crate");
    rbss_codegen::write_crate(&out, &a).unwrap();
    let stale = rbss_codegen::stale_files(&out, &b);
    assert!(
        !stale.is_empty(),
        "a changed source must make the crate stale"
    );
}

/// Golden files: every `codegen/tests/import/ui/NAME.{urdf,xml,sdf}` fails to import (a model
/// file `NAME.toml` there is parsed instead, when there is one), and its report equals
/// `NAME.stderr`.
#[test]
fn importer_errors_match_their_golden_files() {
    let dir = here().join("ui");
    let bless = std::env::var("RBSS_BLESS").is_ok_and(|v| v == "1");
    let mut cases: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.extension()
                .is_some_and(|x| x == "urdf" || x == "xml" || x == "sdf" || x == "toml")
        })
        .collect();
    cases.sort();
    // A source named by a model file of the same stem is tested through the model file.
    let stems_with_toml: Vec<String> = cases
        .iter()
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    let mut failures = Vec::new();
    let mut checked = 0;
    std::env::set_current_dir(here()).unwrap();
    for case in &cases {
        let stem = case.file_stem().unwrap().to_string_lossy().into_owned();
        let ext = case.extension().unwrap().to_string_lossy().into_owned();
        if ext != "toml" && stems_with_toml.contains(&stem) {
            continue;
        }
        let shown = format!("ui/{stem}.{ext}");
        let report = if ext == "toml" {
            let source = std::fs::read_to_string(case).unwrap();
            match parse_model(&shown, &source) {
                Ok(_) => {
                    failures.push(format!("{shown}: parsed without errors"));
                    continue;
                }
                Err(d) => d.render(),
            }
        } else {
            let format = rbss_codegen::import::Format::from_path(case).unwrap();
            match rbss_codegen::import::import_file(Path::new(&shown), &shown, format) {
                Ok(_) => {
                    failures.push(format!("{shown}: imported without errors"));
                    continue;
                }
                Err(d) => d.render(),
            }
        };
        checked += 1;
        let golden = dir.join(format!("{stem}.stderr"));
        if bless {
            std::fs::write(&golden, &report).unwrap();
            continue;
        }
        match std::fs::read_to_string(&golden) {
            Ok(expected) if expected == report => {}
            Ok(expected) => failures.push(format!(
                "{shown}: report differs from {stem}.stderr\n--- expected\n{expected}\n--- actual\n{report}"
            )),
            Err(_) => failures.push(format!("{shown}: no {stem}.stderr; actual:\n{report}")),
        }
    }
    assert!(checked > 0, "no golden cases");
    assert!(
        failures.is_empty(),
        "{}\n\nrun `RBSS_BLESS=1 cargo test --release -p rbss-codegen --test import` to accept",
        failures.join("\n\n")
    );
}

/// Hostile sources: 100 000 nested elements, a 100 MB file, entities, NaN. Each is a located
/// error (no panic, no stack overflow), and `rbss-codegen import --out` writes nothing.
#[test]
fn hostile_xml_is_refused_cleanly() {
    use rbss_codegen::import::{Format, import_file};
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, text: &[u8]| {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let shown = path.display().to_string();
        let format = Format::from_path(&path).unwrap();
        match import_file(&path, &shown, format) {
            Ok(_) => panic!("{name} imported"),
            Err(d) => d.render(),
        }
    };
    let n = 100_000;
    let deep = format!(
        "<mujoco><worldbody>{}{}</worldbody></mujoco>",
        "<body>".repeat(n),
        "</body>".repeat(n)
    );
    let report = run("deep.xml", deep.as_bytes());
    assert!(report.contains("nested more than 256 deep"), "{report}");

    let big = dir.path().join("big.urdf");
    let f = std::fs::File::create(&big).unwrap();
    f.set_len(100 << 20).unwrap();
    drop(f);
    let report = match import_file(&big, "big.urdf", Format::Urdf) {
        Ok(_) => panic!("a 100 MB file imported"),
        Err(d) => d.render(),
    };
    assert!(report.contains("104857600 bytes, more than"), "{report}");

    // A 100 MB mesh file, a binary STL whose count runs past its end, a mesh of NaN: located
    // errors, no panic.
    let f = std::fs::File::create(dir.path().join("big.stl")).unwrap();
    f.set_len(100 << 20).unwrap();
    drop(f);
    let mut short = vec![0u8; 84 + 50];
    short[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
    std::fs::write(dir.path().join("short.stl"), short).unwrap();
    std::fs::write(
        dir.path().join("nan.obj"),
        "v 0 0 0\nv 1 0 NaN\nv 0 1 0\nv 0 0 1\n",
    )
    .unwrap();
    let meshes = "<mujoco><asset><mesh file=\"big.stl\"/><mesh file=\"short.stl\"/><mesh file=\"nan.obj\"/></asset><worldbody><body><freejoint/><geom type=\"mesh\" mesh=\"big\"/><geom type=\"mesh\" mesh=\"short\"/><geom type=\"mesh\" mesh=\"nan\"/></body></worldbody></mujoco>";
    let report = run("meshes.xml", meshes.as_bytes());
    assert!(
        report.contains("104857600 bytes, more than the"),
        "{report}"
    );
    assert!(
        report.contains("a binary STL of 4294967295 triangles"),
        "{report}"
    );
    assert!(
        report.contains("line 2: `v` needs three finite numbers"),
        "{report}"
    );

    let laughs = "<?xml version=\"1.0\"?><!DOCTYPE r [<!ENTITY a \"aaaa\"><!ENTITY b \"&a;&a;&a;\">]><robot name=\"&b;\"/>";
    let report = run("laughs.urdf", laughs.as_bytes());
    assert!(report.contains("DTD"), "{report}");

    let nan = "<robot name=\"r\"><link name=\"a\"/><link name=\"b\"/><joint name=\"j\" type=\"revolute\"><parent link=\"a\"/><child link=\"b\"/><origin xyz=\"0 NaN 0\"/></joint></robot>";
    let report = run("nan.urdf", nan.as_bytes());
    assert!(report.contains("`NaN` is not a finite number"), "{report}");

    // The command writes nothing for a bad source.
    let out = dir.path().join("out.toml");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_rbss-codegen"))
        .arg("import")
        .arg(dir.path().join("nan.urdf"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(!status.status.success());
    assert!(String::from_utf8_lossy(&status.stderr).contains("is not a finite number"));
    assert!(!out.exists(), "a model was written for a bad source");
    // And a good one is written, and is TOML.
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_rbss-codegen"))
        .arg("import")
        .arg(here().join("ur5.urdf"))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    let written = std::fs::read_to_string(&out).unwrap();
    assert!(written.contains("name = \"upper_arm_link\""));
    assert!(written.parse::<toml::Table>().is_ok());
}

/// Real files unchanged: a joint named with a Rust keyword (SDF's `static`, URDF's `type`)
/// becomes `static_` / `type_`, the comment of the written model keeps the source's name; an
/// MJCF actuator on a tendon, the tendon and the sensors are skipped with a warning each and
/// the rest imports (the arm's joint actuator stays the input).
#[test]
fn keyword_names_are_mapped_and_tendons_and_sensors_skipped() {
    use rbss_codegen::import::{Format, import_file};
    let dir = tempfile::tempdir().unwrap();
    let urdf = dir.path().join("kw.urdf");
    std::fs::write(
        &urdf,
        "<robot name=\"kw\"><link name=\"base\"/><link name=\"static\"><inertial><mass value=\"1\"/>\
         <inertia ixx=\"0.1\" iyy=\"0.1\" izz=\"0.1\" ixy=\"0\" ixz=\"0\" iyz=\"0\"/></inertial></link>\
         <joint name=\"type\" type=\"revolute\"><parent link=\"base\"/><child link=\"static\"/>\
         <axis xyz=\"0 0 1\"/></joint></robot>",
    )
    .unwrap();
    let (m, warnings) =
        import_file(&urdf, "kw.urdf", Format::Urdf).unwrap_or_else(|e| panic!("{}", e.render()));
    assert!(warnings.items.is_empty(), "{}", warnings.render_warnings());
    assert_eq!(m.coordinates[0].name, "type_");
    assert_eq!(m.bodies[0].name, "static_");
    assert_eq!(m.actuated, ["type_"]);
    let text = m.render();
    assert!(text.contains("<joint name=\"type\">"), "{text}");
    // The model file of one line generates (no loop, no outputs).
    std::fs::write(dir.path().join("kw.toml"), "urdf = \"kw.urdf\"\n").unwrap();
    let model = model_at(&dir.path().join("kw.toml"));
    assert_eq!(model.coordinates[0].name, "type_");
    assert!(model.outputs.is_empty() && model.loops.is_empty());
    derived(&model);

    let sdf = dir.path().join("kw.sdf");
    std::fs::write(
        &sdf,
        "<sdf version=\"1.7\"><model name=\"kw\"><link name=\"arm\"><inertial><mass>1</mass>\
         <inertia><ixx>0.1</ixx><iyy>0.1</iyy><izz>0.1</izz></inertia></inertial></link>\
         <joint name=\"static\" type=\"revolute\"><parent>world</parent><child>arm</child>\
         <axis><xyz>0 0 1</xyz></axis></joint></model></sdf>",
    )
    .unwrap();
    let (m, _) =
        import_file(&sdf, "kw.sdf", Format::Sdf).unwrap_or_else(|e| panic!("{}", e.render()));
    assert_eq!(m.coordinates[0].name, "static_");

    let mjcf = dir.path().join("tendon.xml");
    std::fs::write(
        &mjcf,
        "<mujoco model=\"tendon\"><worldbody><body name=\"arm\"><joint name=\"a\" axis=\"0 0 1\"/>\
         <inertial pos=\"0.1 0 0\" mass=\"1\" diaginertia=\"0.01 0.01 0.01\"/>\
         <body name=\"fore\" pos=\"0.2 0 0\"><joint name=\"b\" axis=\"0 0 1\"/>\
         <inertial pos=\"0.1 0 0\" mass=\"1\" diaginertia=\"0.01 0.01 0.01\"/></body></body></worldbody>\
         <tendon><fixed name=\"couple\"><joint joint=\"a\" coef=\"1\"/><joint joint=\"b\" coef=\"-1\"/></fixed></tendon>\
         <actuator><motor joint=\"a\"/><motor name=\"pull\" tendon=\"couple\"/></actuator>\
         <sensor><jointpos joint=\"a\"/></sensor></mujoco>",
    )
    .unwrap();
    let (m, warnings) =
        import_file(&mjcf, "tendon.xml", Format::Mjcf).unwrap_or_else(|e| panic!("{}", e.render()));
    let report = warnings.render_warnings();
    assert_eq!(warnings.items.len(), 3, "{report}");
    assert!(
        report.contains("actuator `pull` is skipped: its transmission is `tendon`"),
        "{report}"
    );
    assert!(report.contains("tendon `couple` is skipped"), "{report}");
    assert!(report.contains("sensors are skipped"), "{report}");
    assert_eq!(m.actuated, ["a"]);
}

/// The model file renames imported joints and bodies (`[rename]`, by the source's names): SDF's
/// joint `static` becomes `static_joint` instead of `static_`, a URDF joint and link get names
/// of the user's choice, everything naming them follows (the mimic loop, the child's parent,
/// the actuated list), the written model's comments and a note keep the source's names, and an
/// error about a renamed joint is reported at its element in the source.
#[test]
fn renames_from_the_model_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("arm.urdf"),
        "<robot name=\"arm\"><link name=\"base\"/>\n\
         <link name=\"static\"><inertial><mass value=\"1\"/><inertia ixx=\"0.1\" iyy=\"0.1\" izz=\"0.1\"/></inertial></link>\n\
         <link name=\"fore-arm\"><inertial><mass value=\"1\"/><inertia ixx=\"0.1\" iyy=\"0.1\" izz=\"0.1\"/></inertial></link>\n\
         <joint name=\"type\" type=\"revolute\"><parent link=\"base\"/><child link=\"static\"/><axis xyz=\"0 0 1\"/></joint>\n\
         <joint name=\"j2\" type=\"revolute\"><origin xyz=\"0 0 0.3\"/><parent link=\"static\"/><child link=\"fore-arm\"/>\
         <axis xyz=\"0 1 0\"/><mimic joint=\"type\" multiplier=\"2\"/></joint>\n</robot>\n",
    )
    .unwrap();
    let model_file = dir.path().join("arm.toml");
    std::fs::write(
        &model_file,
        "urdf = \"arm.urdf\"\n[rename]\njoints = { type = \"shoulder\" }\nbodies = { static = \"upper\", fore-arm = \"fore\" }\n",
    )
    .unwrap();
    let model = model_at(&model_file);
    let coords: Vec<&str> = model.coordinates.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(coords, ["shoulder", "j2"]);
    let bodies: Vec<&str> = model.bodies.iter().map(|b| b.name.as_str()).collect();
    assert_eq!(bodies, ["upper", "fore"]);
    let actuated: Vec<&str> = model
        .actuated
        .iter()
        .map(|&k| model.coordinates[k].name.as_str())
        .collect();
    assert_eq!(actuated, ["shoulder"]);
    let text = &model.import.as_ref().unwrap().text;
    assert!(text.contains("b = \"shoulder\""), "{text}");
    assert!(text.contains("parent = \"upper\""), "{text}");
    assert!(text.contains("<joint name=\"type\">"), "{text}");
    assert!(
        text.contains("joint `type` of ") && text.contains("is `shoulder` here"),
        "{text}"
    );
    derived(&model);

    // A rename onto a name the source already has (the joint `j2`; the link `fore-arm`, kept as
    // `fore_arm`): at the `[rename]` entries of the model file, not as a duplicate in the source.
    std::fs::write(
        &model_file,
        "urdf = \"arm.urdf\"\n[rename]\njoints = { type = \"j2\" }\nbodies = { static = \"fore_arm\" }\n",
    )
    .unwrap();
    let shown = model_file.display().to_string();
    let err = parse_model(&shown, &std::fs::read_to_string(&model_file).unwrap()).unwrap_err();
    let report = err.render();
    assert_eq!(err.items.len(), 2, "{report}");
    assert!(
        report.contains("arm.toml:3:12")
            && report.contains("joint `type` cannot be renamed `j2`: ")
            && report.contains("arm.urdf's joint `j2` has that name"),
        "{report}"
    );
    assert!(
        report.contains("arm.toml:4:12")
            && report.contains("body `static` cannot be renamed `fore_arm`: ")
            && report.contains("body `fore-arm` has that name")
            && report.contains("or rename `fore-arm` too"),
        "{report}"
    );

    // An error about a renamed joint (it mimics itself): at its `<mimic>` in the URDF, under
    // its new name, not at a line of the merged text.
    let urdf = std::fs::read_to_string(dir.path().join("arm.urdf")).unwrap();
    std::fs::write(
        dir.path().join("arm.urdf"),
        urdf.replace("<mimic joint=\"type\"", "<mimic joint=\"j2\""),
    )
    .unwrap();
    std::fs::write(
        &model_file,
        "urdf = \"arm.urdf\"\n[rename]\njoints = { j2 = \"elbow\" }\n",
    )
    .unwrap();
    let shown = model_file.display().to_string();
    let err = parse_model(&shown, &std::fs::read_to_string(&model_file).unwrap()).unwrap_err();
    let report = err.render();
    assert_eq!(err.items.len(), 1, "{report}");
    assert!(
        report.contains("arm.urdf:5:") && report.contains("coupling `mimic_elbow`"),
        "{report}"
    );
    assert!(report.contains("<mimic joint=\"j2\""), "{report}");

    // SDF's `static`, the issue's case: renamed instead of mapped to `static_`.
    std::fs::write(
        dir.path().join("kw.sdf"),
        "<sdf version=\"1.7\"><model name=\"kw\"><link name=\"arm\"><inertial><mass>1</mass>\
         <inertia><ixx>0.1</ixx><iyy>0.1</iyy><izz>0.1</izz></inertia></inertial></link>\
         <joint name=\"static\" type=\"revolute\"><parent>world</parent><child>arm</child>\
         <axis><xyz>0 0 1</xyz></axis></joint></model></sdf>",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("kw.toml"),
        "sdf = \"kw.sdf\"\nrename.joints = { static = \"static_joint\" }\n",
    )
    .unwrap();
    let model = model_at(&dir.path().join("kw.toml"));
    assert_eq!(model.coordinates[0].name, "static_joint");
    assert_eq!(model.actuated, [0]);
}

/// A floating base from each format: an MJCF `<freejoint>` has the kernels of the same robot
/// written with a `free` joint in TOML (MuJoCo's qpos: the body's world pose, homes as written);
/// an SDF root link no joint holds and a URDF `floating` joint import as free joints too, with
/// the trunk at its written pose at home and one `unit_norm` constraint.
#[test]
fn floating_bases_import_as_free_joints() {
    use rbss_codegen::import::{Format, import_file};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let trunk =
        "<inertial pos=\"0.01 0 0.02\" mass=\"5\" fullinertia=\"0.2 0.25 0.3 0.01 0 0.02\"/>";
    std::fs::write(
        d.join("fb.xml"),
        format!(
            "<mujoco model=\"fb\"><worldbody><body name=\"trunk\" pos=\"0.1 0 1\" euler=\"0 0 30\">\
             <freejoint name=\"root\"/>{trunk}<body name=\"leg\" pos=\"0 0.1 -0.1\">\
             <joint name=\"hip\" axis=\"0 1 0\"/><inertial pos=\"0 0 -0.1\" mass=\"1\" \
             diaginertia=\"0.01 0.01 0.001\"/></body></body></worldbody>\
             <actuator><motor joint=\"hip\"/></actuator></mujoco>"
        ),
    )
    .unwrap();
    std::fs::write(d.join("fb_mjcf.toml"), "mjcf = \"fb.xml\"\n").unwrap();
    std::fs::write(
        d.join("fb.toml"),
        "coordinates = [\n\
         { name = \"root_x\", unit = \"m\" }, { name = \"root_y\", unit = \"m\" }, { name = \"root_z\", unit = \"m\" },\n\
         { name = \"root_qw\", unit = \"1\", home = 1 }, { name = \"root_qx\", unit = \"1\" },\n\
         { name = \"root_qy\", unit = \"1\" }, { name = \"root_qz\", unit = \"1\" },\n\
         { name = \"hip\", unit = \"rad\" },\n]\n\
         [robot]\nname = \"fb\"\ngravity = [0, 0, -9.81]\nactuated = [\"hip\"]\n\
         [[body]]\nname = \"trunk\"\n\
         transforms = [{ free = [\"root_x\", \"root_y\", \"root_z\", \"root_qw\", \"root_qx\", \"root_qy\", \"root_qz\"] }]\n\
         mass = 5\ncom = [0.01, 0, 0.02]\ninertia = [0.2, 0.25, 0.3, 0.01, 0, 0.02]\n\
         [[body]]\nname = \"leg\"\nparent = \"trunk\"\n\
         transforms = [{ pose = { xyz = [0, 0.1, -0.1] } }, { revolute = \"hip\", axis = \"y\" }]\n\
         mass = 1\ncom = [0, 0, -0.1]\ninertia = [0.01, 0.01, 0.001, 0, 0, 0]\n",
    )
    .unwrap();
    let (imported, _) = import_file(&d.join("fb.xml"), "fb.xml", Format::Mjcf)
        .unwrap_or_else(|e| panic!("{}", e.render()));
    let homes: Vec<Option<String>> = imported
        .coordinates
        .iter()
        .map(|c| c.home.clone())
        .collect();
    assert_eq!(homes[0].as_deref(), Some("0.1"));
    assert_eq!(homes[2].as_deref(), Some("1.0"));
    let mjcf = model_at(&d.join("fb_mjcf.toml"));
    let toml = model_at(&d.join("fb.toml"));
    assert_eq!(mjcf.loops.len(), 1);
    assert_eq!(mjcf.loops[0].name, "trunk_quat");
    let worst = worst_difference(&mjcf, &toml);
    assert!(worst < 1e-12, "MJCF free joint against TOML: {worst:e}");

    // The trunk at its written pose at home, for every format.
    let pose_at_home = |m: &Model| -> ([f64; 3], [[f64; 3]; 3]) {
        let dv = derived(m);
        let x: Vec<f64> = m.coordinates.iter().map(|c| c.home).collect();
        let p: Vec<f64> = m.parameters.iter().map(|q| q.value).collect();
        let vals = dv.graph.eval_all(&x, &vec![0.0; x.len()], &p);
        let fr = &dv.frames[0];
        (
            std::array::from_fn(|i| vals[fr.p[i] as usize]),
            std::array::from_fn(|i| std::array::from_fn(|j| vals[fr.r[i][j] as usize])),
        )
    };
    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let want = (
        [0.1, 0.0, 1.0],
        [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
    );
    let close = |a: &([f64; 3], [[f64; 3]; 3]), b: &([f64; 3], [[f64; 3]; 3])| {
        (0..3).all(|i| (a.0[i] - b.0[i]).abs() < 1e-12)
            && (0..3).all(|i| (0..3).all(|j| (a.1[i][j] - b.1[i][j]).abs() < 1e-12))
    };
    assert!(close(&pose_at_home(&mjcf), &want));
    std::fs::write(
        d.join("fb.sdf"),
        "<sdf version=\"1.7\"><model name=\"fb\"><link name=\"trunk\"><pose>0.1 0 1 0 0 0.5235987755982988</pose>\
         <inertial><mass>5</mass><inertia><ixx>0.1</ixx><iyy>0.2</iyy><izz>0.3</izz></inertia></inertial></link>\
         <link name=\"leg\"><pose relative_to=\"trunk\">0 0.1 -0.1 0 0 0</pose><inertial><mass>1</mass>\
         <inertia><ixx>0.01</ixx><iyy>0.01</iyy><izz>0.001</izz></inertia></inertial></link>\
         <joint name=\"hip\" type=\"revolute\"><parent>trunk</parent><child>leg</child>\
         <axis><xyz>0 1 0</xyz></axis></joint></model></sdf>",
    )
    .unwrap();
    std::fs::write(d.join("fb_sdf.toml"), "sdf = \"fb.sdf\"\n").unwrap();
    let sdf = model_at(&d.join("fb_sdf.toml"));
    assert_eq!(sdf.coordinates[0].name, "trunk_free_x");
    assert_eq!((sdf.coordinates.len(), sdf.loops.len()), (8, 1));
    assert!(close(&pose_at_home(&sdf), &want));
    std::fs::write(
        d.join("fb.urdf"),
        "<robot name=\"fb\"><link name=\"world\"/><joint name=\"root\" type=\"floating\">\
         <origin xyz=\"0.1 0 1\" rpy=\"0 0 0.5235987755982988\"/><parent link=\"world\"/><child link=\"trunk\"/></joint>\
         <link name=\"trunk\"><inertial><mass value=\"5\"/><inertia ixx=\"0.1\" iyy=\"0.2\" izz=\"0.3\" ixy=\"0\" ixz=\"0\" iyz=\"0\"/></inertial></link>\
         <joint name=\"hip\" type=\"revolute\"><origin xyz=\"0 0.1 -0.1\"/><axis xyz=\"0 1 0\"/><parent link=\"trunk\"/><child link=\"leg\"/></joint>\
         <link name=\"leg\"><inertial><mass value=\"1\"/><inertia ixx=\"0.01\" iyy=\"0.01\" izz=\"0.001\" ixy=\"0\" ixz=\"0\" iyz=\"0\"/></inertial></link></robot>",
    )
    .unwrap();
    std::fs::write(d.join("fb_urdf.toml"), "urdf = \"fb.urdf\"\n").unwrap();
    let urdf = model_at(&d.join("fb_urdf.toml"));
    assert_eq!(urdf.coordinates[3].name, "root_qw");
    assert_eq!(urdf.actuated.len(), 1);
    assert!(close(&pose_at_home(&urdf), &want));
}

/// `f` of a model at `x` (velocities zero), by the coordinates' names.
fn f_at(m: &Model, at: &[(&str, f64)]) -> Vec<f64> {
    let x: Vec<f64> = m
        .coordinates
        .iter()
        .map(|c| at.iter().find(|(n, _)| *n == c.name).unwrap().1)
        .collect();
    let d = derived(m);
    let p: Vec<f64> = m.parameters.iter().map(|q| q.value).collect();
    d.f.iter()
        .map(|&i| d.graph.eval(i, &x, &vec![0.0; x.len()], &p))
        .collect()
}

/// SDF `gearbox` joints are couplings with SDFormat's sign, `theta_2 = -gearbox_ratio *
/// theta_1` (both angles against `<gearbox_reference_body>`, about `<axis>` and `<axis2>`):
/// gearbox.sdf's driven shaft turns about -z, so the coupling is `j2 = 2 j1`; with `<axis2>`
/// along -z too it is `j2 = -2 j1`. The imported robot derives the kernels of gearbox.toml,
/// written by hand, and the driven joint is not actuated.
#[test]
fn sdf_gearbox_joints_are_couplings() {
    let plain = model_at(&here().join("gearbox.toml"));
    let imported = model_at(&here().join("gearbox_sdf.toml"));
    let names = |m: &Model, idx: &[usize]| {
        idx.iter()
            .map(|&i| m.coordinates[i].name.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(names(&imported, &imported.actuated), ["j1"]);
    assert_eq!(imported.loops.len(), 1);
    assert_eq!(imported.loops[0].name, "mesh");
    // f = j2 - ratio j1: zero on j2 = 2 j1, -1.2 on the other sign.
    let on = f_at(&imported, &[("j1", 0.3), ("j2", 0.6)]);
    let off = f_at(&imported, &[("j1", 0.3), ("j2", -0.6)]);
    assert!(on[0].abs() < 1e-15, "f on the coupling: {on:?}");
    assert!((off[0] + 1.2).abs() < 1e-15, "f off the coupling: {off:?}");
    let worst = worst_difference(&plain, &imported);
    println!("gearbox from SDF vs gearbox.toml: worst relative difference {worst:e}");
    assert!(worst < 1e-12, "worst {worst:e}");

    // `<axis2>` along -z, as j2: theta_2 = j2, theta_1 = j1, so j2 = -2 j1.
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(here().join("gearbox.sdf")).unwrap();
    let flipped = text.replace(
        "<axis2><xyz>0 0 1</xyz></axis2>",
        "<axis2><xyz>0 0 -1</xyz></axis2>",
    );
    assert_ne!(flipped, text);
    std::fs::write(dir.path().join("gearbox.sdf"), flipped).unwrap();
    std::fs::write(dir.path().join("m.toml"), "sdf = \"gearbox.sdf\"\n").unwrap();
    let m = model_at(&dir.path().join("m.toml"));
    let on = f_at(&m, &[("j1", 0.3), ("j2", -0.6)]);
    let off = f_at(&m, &[("j1", 0.3), ("j2", 0.6)]);
    assert!(on[0].abs() < 1e-15, "f on the coupling: {on:?}");
    assert!((off[0] - 1.2).abs() < 1e-15, "f off the coupling: {off:?}");
}

/// A prismatic joint that closes a loop (slider_crank.sdf's `slide`, whose guide the tree
/// reaches after the slider) is a coordinate, and the joint that brought the slider in (`pin`)
/// closes the loop; a note says so. The loop closes at the hand-computed assembly of the
/// slider-crank (`a sin th + b sin(th + k) = 0`, the slider at `a cos th + b cos(th + k)`), not
/// off it, and the robot derives the kernels of slider_crank.toml, written by hand.
#[test]
fn sdf_prismatic_joint_closing_a_loop_is_a_coordinate() {
    use rbss_codegen::import::{Format, import_file};
    let (imp, _) = import_file(
        &here().join("slider_crank.sdf"),
        "slider_crank.sdf",
        Format::Sdf,
    )
    .unwrap_or_else(|e| panic!("{}", e.render()));
    let coords: Vec<&str> = imp.coordinates.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(coords, ["th", "k", "slide"]);
    assert_eq!(imp.coordinates[2].unit, "m");
    assert_eq!(imp.loops.len(), 1);
    assert_eq!(imp.loops[0].keys[0], ("name", "\"pin\"".to_string()));
    assert!(
        imp.notes
            .iter()
            .any(|n| n.contains("`slide`") && n.contains("`pin`")),
        "{:?}",
        imp.notes
    );

    let plain = model_at(&here().join("slider_crank.toml"));
    let imported = model_at(&here().join("slider_crank_sdf.toml"));
    let (a, b, x0) = (0.1, 0.3, 0.4);
    for th in [0.7f64, -1.9, 2.8] {
        let phi = -(a * th.sin() / b).asin(); // th + k, the pin on the x axis
        let k = phi - th;
        let slide = a * th.cos() + b * phi.cos() - x0;
        let at = [("th", th), ("k", k), ("slide", slide)];
        let f = f_at(&imported, &at);
        assert_eq!(f.len(), 2);
        assert!(f.iter().all(|v| v.abs() < 1e-15), "th {th}: f {f:?}");
        // The slider moved by 1 mm along the guide: the pin is 1 mm short in x.
        let moved = f_at(&imported, &[("th", th), ("k", k), ("slide", slide + 1e-3)]);
        assert!(
            (moved[0] + 1e-3).abs() < 1e-15 && moved[1].abs() < 1e-15,
            "th {th}: f {moved:?}"
        );
    }
    let worst = worst_difference(&plain, &imported);
    println!("slider-crank from SDF vs slider_crank.toml: worst relative difference {worst:e}");
    assert!(worst < 1e-12, "worst {worst:e}");

    // It generates: the home assembled with the output k = -0.9 held is the hand solution,
    // tan th = b sin(-k) / (a + b cos k).
    let path = here().join("slider_crank_sdf.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let generated = rbss_codegen::generate(
        path.to_str().unwrap(),
        &text,
        &rbss_codegen::Options::default(),
        &mut |_| {},
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let k: f64 = -0.9;
    let th = (b * (-k).sin()).atan2(a + b * k.cos());
    let slide = a * th.cos() + b * (th + k).cos() - x0;
    let home = &generated.report.home;
    println!("slider-crank home {home:?}, by hand [{th}, {k}, {slide}]");
    for (got, want) in home.iter().zip([th, k, slide]) {
        assert!(
            (got - want).abs() < 1e-12,
            "home {home:?}, by hand [{th}, {k}, {slide}]"
        );
    }
}

/// MuJoCo 4.0.0's equality rows for couplings.xml at two `qpos` (`efc_pos`, then the rows of
/// `efc_J`, equalities bend, pull, lock), measured with bench/peers' venv:
/// `m = mujoco.MjModel.from_xml_path("codegen/tests/import/couplings.xml"); d.qpos[:] = X;
/// mujoco.mj_forward(m, d)`, printed with `repr`.
#[allow(clippy::type_complexity)]
const MUJOCO_EQUALITIES: [([f64; 5], [f64; 3], [[f64; 5]; 3]); 2] = [
    (
        [0.7, -0.4, 0.25, 0.5, -0.3],
        [
            -0.5633600000000001,
            0.12460937499999991,
            -0.6000000000000001,
        ],
        [
            [-0.8615999999999999, 1.0, 0.0, 0.0, 0.0],
            [2.0, 0.0, -0.5, -1.5281250000000002, 0.0],
            [0.0, 0.0, 0.0, 0.0, 1.0],
        ],
    ),
    (
        [-0.2, 0.9, -0.1, -0.8, 0.6],
        [1.19375, -1.1593600000000002, 0.3],
        [
            [-0.30000000000000004, 1.0, 0.0, 0.0, 0.0],
            [2.0, 0.0, -0.5, 1.5168000000000008, 0.0],
            [0.0, 0.0, 0.0, 0.0, 1.0],
        ],
    ),
];

/// MuJoCo's polynomial equalities (couplings.xml): a joint equality of degree 4 between hinges
/// with `ref`, a fixed-tendon equality of degree 4, a joint held at a constant (no `joint2`).
/// The imported robot derives the kernels of couplings.toml, written by hand; its `f` and `G`
/// are MuJoCo's `efc_pos` and `efc_J` rows; `f` vanishes on a motion that satisfies the
/// polynomials; `G` agrees with central differences of `f` and `gamma` with second differences
/// along motions (on the couplings, `G Ẍ = gamma`; off them, `gamma = G Ẍ - f̈`).
#[test]
fn mjcf_polynomial_and_tendon_equalities_are_couplings() {
    let plain = model_at(&here().join("couplings.toml"));
    let imported = model_at(&here().join("couplings_mjcf.toml"));
    let worst = worst_difference(&plain, &imported);
    println!("couplings from MJCF vs couplings.toml: worst relative difference {worst:e}");
    assert!(worst < 1e-12, "worst {worst:e}");

    // The coupled tendons are not skipped; a coupled tendon's stiffness is, with a warning.
    use rbss_codegen::import::{Format, import_file};
    let xml = here().join("couplings.xml");
    let (_, warnings) = import_file(&xml, "couplings.xml", Format::Mjcf)
        .unwrap_or_else(|e| panic!("{}", e.render()));
    assert!(warnings.items.is_empty(), "{}", warnings.render_warnings());
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(&xml).unwrap();
    let stiff = text.replace(
        "<fixed name=\"t2\">",
        "<fixed name=\"t2\" stiffness=\"10\">",
    );
    assert_ne!(stiff, text);
    std::fs::write(dir.path().join("stiff.xml"), stiff).unwrap();
    let (_, warnings) = import_file(&dir.path().join("stiff.xml"), "stiff.xml", Format::Mjcf)
        .unwrap_or_else(|e| panic!("{}", e.render()));
    let report = warnings.render_warnings();
    assert_eq!(warnings.items.len(), 1, "{report}");
    assert!(
        report.contains("tendon `t2`'s stiffness is not applied"),
        "{report}"
    );

    let names: Vec<&str> = imported
        .coordinates
        .iter()
        .map(|c| c.name.as_str())
        .collect();
    assert_eq!(names, ["j1", "j2", "s3", "j4", "j5"], "MuJoCo's qpos order");
    let d = derived(&imported);
    assert_eq!(d.m, 3);
    let p: Vec<f64> = imported.parameters.iter().map(|q| q.value).collect();
    let f = |x: &[f64]| -> Vec<f64> {
        d.f.iter()
            .map(|&i| d.graph.eval(i, x, &[0.0; 5], &p))
            .collect()
    };
    let g = |x: &[f64]| -> Vec<Vec<f64>> {
        d.g.iter()
            .map(|row| {
                row.iter()
                    .map(|&i| d.graph.eval(i, x, &[0.0; 5], &p))
                    .collect()
            })
            .collect()
    };
    let gamma = |x: &[f64], v: &[f64]| -> Vec<f64> {
        d.gamma.iter().map(|&i| d.graph.eval(i, x, v, &p)).collect()
    };
    let mut worst_mj = 0.0f64;
    for (x, pos, jac) in &MUJOCO_EQUALITIES {
        let (fx, gx) = (f(x), g(x));
        for r in 0..3 {
            worst_mj = worst_mj.max((fx[r] - pos[r]).abs());
            for c in 0..5 {
                worst_mj = worst_mj.max((gx[r][c] - jac[r][c]).abs());
            }
        }
    }
    println!("f, G against MuJoCo's efc_pos, efc_J: worst difference {worst_mj:e}");
    assert!(worst_mj < 1e-14, "against MuJoCo: {worst_mj:e}");

    // A motion on the couplings: j1 and j4 free, j2, s3 and j5 from the polynomials.
    let p1 = |u: f64| 0.1 + 0.5 * u + 0.3 * u * u + 0.2 * u.powi(3) + 0.1 * u.powi(4);
    let p2 = |w: f64| 0.05 + 0.4 * w + 0.3 * w * w + 0.1 * w.powi(4);
    let on = |t: f64| -> [f64; 5] {
        let j1 = 0.3 + 0.4 * t.sin();
        let j4 = 0.6 * (1.3 * t).cos();
        let j2 = -0.2 + p1(j1 - 0.3);
        let s3 = (2.0 * j1 - 0.6 - p2(1.5 * j4)) / 0.5;
        [j1, j2, s3, j4, 0.3]
    };
    let h = 1e-4;
    let (mut worst_f, mut worst_on) = (0.0f64, 0.0f64);
    for k in 0..8 {
        let t = 0.7 * k as f64 - 2.0;
        let (x0, xp, xm) = (on(t), on(t + h), on(t - h));
        worst_f = worst_f.max(f(&x0).iter().fold(0.0, |a, b| a.max(b.abs())));
        let v: Vec<f64> = (0..5).map(|i| (xp[i] - xm[i]) / (2.0 * h)).collect();
        let a: Vec<f64> = (0..5)
            .map(|i| (xp[i] - 2.0 * x0[i] + xm[i]) / (h * h))
            .collect();
        let (gx, gam) = (g(&x0), gamma(&x0, &v));
        for r in 0..3 {
            let ga: f64 = (0..5).map(|c| gx[r][c] * a[c]).sum();
            worst_on = worst_on.max((ga - gam[r]).abs() / (1.0 + gam[r].abs()));
        }
    }
    println!("on the couplings: max |f| {worst_f:e}, |G Xddot - gamma| {worst_on:e}");
    assert!(worst_f < 1e-14, "f on the couplings: {worst_f:e}");
    assert!(
        worst_on < 1e-6,
        "G Xddot - gamma on the couplings: {worst_on:e}"
    );

    // Off the couplings, at random states: G by central differences of f; gamma = G A - f̈
    // along the motion X0 + V t + A t² / 2, f̈ by second differences.
    let mut seed = 0x5eed_0f34_b000_0001u64;
    let (mut worst_g, mut worst_gamma) = (0.0f64, 0.0f64);
    for _ in 0..16 {
        let x0: Vec<f64> = (0..5).map(|_| random(&mut seed)).collect();
        let v: Vec<f64> = (0..5).map(|_| 2.0 * random(&mut seed)).collect();
        let a: Vec<f64> = (0..5).map(|_| 2.0 * random(&mut seed)).collect();
        let gx = g(&x0);
        for c in 0..5 {
            let hc = f64::EPSILON.cbrt() * x0[c].abs().max(1.0);
            let (mut xp, mut xm) = (x0.clone(), x0.clone());
            xp[c] += hc;
            xm[c] -= hc;
            let (fp, fm) = (f(&xp), f(&xm));
            for r in 0..3 {
                let num = (fp[r] - fm[r]) / (2.0 * hc);
                worst_g = worst_g.max((gx[r][c] - num).abs() / (1.0 + num.abs()));
            }
        }
        let at = |t: f64| -> Vec<f64> {
            (0..5)
                .map(|i| x0[i] + v[i] * t + 0.5 * a[i] * t * t)
                .collect()
        };
        let (f0, fp, fm) = (f(&x0), f(&at(h)), f(&at(-h)));
        let gam = gamma(&x0, &v);
        for r in 0..3 {
            let fdd = (fp[r] - 2.0 * f0[r] + fm[r]) / (h * h);
            let ga: f64 = (0..5).map(|c| gx[r][c] * a[c]).sum();
            let want = ga - fdd;
            worst_gamma = worst_gamma.max((gam[r] - want).abs() / (1.0 + want.abs()));
        }
        // A nonlinear coupling's gamma is not zero off its rest.
        assert!(gam[0] != 0.0 && gam[1] != 0.0, "{gam:?}");
    }
    println!("G vs central differences {worst_g:e}, gamma vs second differences {worst_gamma:e}");
    assert!(worst_g < 1e-8, "G: {worst_g:e}");
    assert!(worst_gamma < 1e-6, "gamma: {worst_gamma:e}");
}

/// Each imported body's mass, centre of mass and inertia entries, by name.
fn masses(path: &Path) -> Vec<(String, f64, [f64; 3], [f64; 6])> {
    use rbss_codegen::import::{Format, import_file};
    let (m, _) = import_file(path, &path.display().to_string(), Format::Mjcf)
        .unwrap_or_else(|e| panic!("{}", e.render()));
    let num = |s: &String| s.parse::<f64>().unwrap_or_else(|_| panic!("`{s}`"));
    m.bodies
        .iter()
        .map(|b| {
            let (mass, com, inertia) = b.mass.as_ref().expect("a body without mass");
            (
                b.name.clone(),
                num(mass),
                com.each_ref().map(num),
                inertia.each_ref().map(num),
            )
        })
        .collect()
}

/// The largest difference of two bodies' mass, com and inertia, relative to the largest of
/// the second body's values of each.
fn mass_difference(all: &[(String, f64, [f64; 3], [f64; 6])], a: &str, b: &str) -> f64 {
    let get = |n: &str| {
        all.iter()
            .find(|x| x.0 == n)
            .unwrap_or_else(|| panic!("no body {n}"))
    };
    let (x, y) = (get(a), get(b));
    let rel = |p: &[f64], q: &[f64]| {
        let scale = q.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
        p.iter()
            .zip(q)
            .fold(0.0f64, |m, (u, v)| m.max((u - v).abs() / scale))
    };
    rel(&[x.1], &[y.1])
        .max(rel(&x.2, &y.2))
        .max(rel(&x.3, &y.3))
}

/// Mesh geoms weigh as the solids they bound (codegen/tests/import/mesh_inertia.xml): a box
/// written as a binary STL, an ASCII STL and an OBJ of quads, turned and moved as the `box`
/// geom beside it; a U-shaped OBJ (offset in its file, so MuJoCo's re-centring is exercised)
/// `exact` as its three boxes, `convex` as its hull's one box, scaled by (2, 0.5, -1) (a
/// left-handed scale turns the faces over) with `mass` as its three scaled boxes. Equal to
/// 1e-12; the mesh and box paths share no arithmetic but the final sum.
#[test]
fn mjcf_mesh_geoms_weigh_as_the_solids_they_bound() {
    let xml = here().join("mesh_inertia.xml");
    let all = masses(&xml);
    for (a, b) in [
        ("as_stl", "as_box"),
        ("as_obj", "as_box"),
        ("u_exact", "u_three_boxes"),
        ("u_convex", "u_hull_box"),
        ("u_scaled", "u_scaled_boxes"),
    ] {
        let d = mass_difference(&all, a, b);
        assert!(d < 1e-12, "{a} vs {b}: {d:e}");
    }
    // `legacy` (MuJoCo's default) counts the U's inner faces' tetrahedra positive: more than
    // the U, less than the hull (MuJoCo 4.0.0: 916.666... kg, mjcf_mesh_inertia_matches_mujoco).
    let mass = |n: &str| all.iter().find(|x| x.0 == n).unwrap().1;
    assert!(mass("u_legacy") > mass("u_exact") && mass("u_legacy") < mass("u_convex"));
    // ASCII STL in the binary's place: the same box.
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(&xml).unwrap();
    let meshes = here().join("meshes");
    let ascii = text
        .replace(
            "meshdir=\"meshes\"",
            &format!("meshdir=\"{}\"", meshes.display()),
        )
        .replace("file=\"box.stl\"", "file=\"box_ascii.stl\"");
    assert_ne!(ascii, text);
    let copy = dir.path().join("mesh_inertia.xml");
    std::fs::write(&copy, ascii).unwrap();
    let all = masses(&copy);
    let d = mass_difference(&all, "as_stl", "as_box");
    assert!(d < 1e-12, "ASCII STL: {d:e}");
}

/// The rotation invariants of an inertia `[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]`: the trace, the sum
/// of the squares of the entries and the determinant's cube root (the principal moments'
/// symmetric functions, in the inertia's units).
fn invariants(i: &[f64]) -> [f64; 3] {
    let [a, b, c, d, e, f] = [i[0], i[1], i[2], i[3], i[4], i[5]];
    let det = a * (b * c - f * f) - d * (d * c - f * e) + e * (d * f - b * e);
    [
        a + b + c,
        (a * a + b * b + c * c + 2.0 * (d * d + e * e + f * f)).sqrt(),
        det.cbrt(),
    ]
}

/// Against MuJoCo: the venv's python (`RBSS_PEERS_PYTHON`, else bench/peers/.venv/bin/python)
/// loads mesh_inertia.xml; every body's `body_mass`, `body_ipos` and `body_inertia` turned by
/// `body_iquat` equal the imported mass, com and principal moments (rotation invariants) to
/// 1e-12 relative to the largest of each, the inertia's entries to 1e-8 (MuJoCo's principal
/// axes are iterated to a tolerance). SKIPPED without that python.
#[test]
fn mjcf_mesh_inertia_matches_mujoco() {
    let python = std::env::var_os("RBSS_PEERS_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("bench/peers/.venv/bin/python"));
    if !python.is_file() {
        println!("SKIPPED: no {} (set RBSS_PEERS_PYTHON)", python.display());
        return;
    }
    let xml = here().join("mesh_inertia.xml");
    let script = r#"
import sys, mujoco, numpy as np
m = mujoco.MjModel.from_xml_path(sys.argv[1])
print(mujoco.__version__)
for i in range(1, m.nbody):
    R = np.zeros(9); mujoco.mju_quat2Mat(R, m.body_iquat[i]); R = R.reshape(3, 3)
    I = R @ np.diag(m.body_inertia[i]) @ R.T
    v = [m.body_mass[i], *m.body_ipos[i], I[0,0], I[1,1], I[2,2], I[0,1], I[0,2], I[1,2]]
    print(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, i), *map(repr, map(float, v)))
"#;
    let out = std::process::Command::new(&python)
        .args(["-c", script])
        .arg(&xml)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let mut lines = text.lines();
    let version = lines.next().unwrap_or("");
    let ours = masses(&xml);
    let (mut worst, mut worst_axes): (f64, f64) = (0.0, 0.0);
    let mut n = 0;
    for line in lines {
        let w: Vec<&str> = line.split_whitespace().collect();
        let v: Vec<f64> = w[1..].iter().map(|s| s.parse().unwrap()).collect();
        let (_, mass, com, inertia) = ours.iter().find(|x| x.0 == w[0]).unwrap();
        let rel = |p: &[f64], q: &[f64]| {
            let scale = q.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
            p.iter()
                .zip(q)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs() / scale))
        };
        let d = rel(&[*mass], &v[0..1])
            .max(rel(com, &v[1..4]))
            .max(rel(&invariants(inertia), &invariants(&v[4..10])));
        assert!(d < 1e-12, "{}: {d:e} (MuJoCo {line})", w[0]);
        // The axes: MuJoCo's eig3 (Jacobi) stops at a tolerance, its principal axes of a mesh
        // with no symmetry are within about 1e-10 (measured 7.9e-10 of the largest entry on
        // `cloud`, whose principal moments agree to 3e-16).
        let axes = rel(inertia, &v[4..10]);
        assert!(axes < 1e-8, "{}: inertia {axes:e} (MuJoCo {line})", w[0]);
        worst = worst.max(d);
        worst_axes = worst_axes.max(axes);
        n += 1;
    }
    assert_eq!(n, ours.len());
    println!(
        "MuJoCo {version}: {n} bodies, worst relative difference {worst:e} (mass, com, principal \
         moments), {worst_axes:e} (inertia entries)"
    );
}

/// The world frame of body `body` (position, rotation) at `x` (by the coordinates' names).
fn frame_at(m: &Model, body: &str, at: &[(&str, f64)]) -> ([f64; 3], [[f64; 3]; 3]) {
    let x: Vec<f64> = m
        .coordinates
        .iter()
        .map(|c| at.iter().find(|(n, _)| *n == c.name).unwrap().1)
        .collect();
    let d = derived(m);
    let p: Vec<f64> = m.parameters.iter().map(|q| q.value).collect();
    let vals = d.graph.eval_all(&x, &vec![0.0; x.len()], &p);
    let k = m.bodies.iter().position(|b| b.name == body).unwrap();
    let fr = &d.frames[k];
    (
        std::array::from_fn(|i| vals[fr.p[i] as usize]),
        std::array::from_fn(|i| std::array::from_fn(|j| vals[fr.r[i][j] as usize])),
    )
}

/// The rotation by `t` about the unit axis `a` (Rodrigues).
fn rot(a: [f64; 3], t: f64) -> [[f64; 3]; 3] {
    let (s, c) = t.sin_cos();
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let k = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]][i][j];
            let e = if i == j { c } else { 0.0 };
            e + s * k + (1.0 - c) * a[i] * a[j]
        })
    })
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

fn mat_vec(a: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| (0..3).map(|k| a[i][k] * v[k]).sum())
}

/// The largest entry of `|a - b|` over a frame's position and rotation.
fn frame_gap(a: &([f64; 3], [[f64; 3]; 3]), b: &([f64; 3], [[f64; 3]; 3])) -> f64 {
    let mut worst = 0.0f64;
    for i in 0..3 {
        worst = worst.max((a.0[i] - b.0[i]).abs());
        for j in 0..3 {
            worst = worst.max((a.1[i][j] - b.1[i][j]).abs());
        }
    }
    worst
}

/// SDF `universal` and `revolute2` joints are two coordinates `NAME_1`, `NAME_2`: the angle about
/// `<axis>`, then about `<axis2>` as turned by the first (two revolute joints in series), both
/// axes in the joint's frame unless `expressed_in` names another (ujoint.sdf's `w`: `<axis>` in a
/// `<frame>` turned 0.3 rad about x, `<axis2>` in the model's frame). The child's frame is
/// `J R(axis, q1) R(axis2, q2) J⁻¹` (J the joint's pose), computed here; the imported robot derives
/// the kernels of ujoint.toml, written by hand.
#[test]
fn sdf_universal_and_revolute2_joints_are_two_angles() {
    let imported = model_at(&here().join("ujoint_sdf.toml"));
    let plain = model_at(&here().join("ujoint.toml"));
    let names: Vec<&str> = imported
        .coordinates
        .iter()
        .map(|c| c.name.as_str())
        .collect();
    assert_eq!(names, ["u_1", "u_2", "w_1", "w_2"]);
    assert_eq!(imported.actuated, [0, 1, 2, 3]);
    let (x, z) = ([1.0, 0.0, 0.0], [0.0, 0.0, 1.0]);
    let tilted_y = [0.0, 0.3f64.cos(), 0.3f64.sin()];
    let mut worst = 0.0f64;
    for (u1, u2, w1, w2) in [(0.4, -0.7, 1.1, 0.3), (-2.0, 1.3, -0.6, 2.5)] {
        let at = [("u_1", u1), ("u_2", u2), ("w_1", w1), ("w_2", w2)];
        // The arm: the joint 0.4 above the world's origin, the arm 0.1 above the joint.
        let ru = mat_mul(&rot(z, u1), &rot(x, u2));
        let pj = [0.0, 0.0, 0.4];
        let d = mat_vec(&ru, [0.0, 0.0, 0.1]);
        let arm = ([pj[0] + d[0], pj[1] + d[1], pj[2] + d[2]], ru);
        // The hand: 0.4 above the arm, turned about tilted y, then about x (turned with it).
        let dh = mat_vec(&ru, [0.0, 0.0, 0.4]);
        let rh = mat_mul(&ru, &mat_mul(&rot(tilted_y, w1), &rot(x, w2)));
        let hand = ([arm.0[0] + dh[0], arm.0[1] + dh[1], arm.0[2] + dh[2]], rh);
        worst = worst.max(frame_gap(&frame_at(&imported, "arm", &at), &arm));
        worst = worst.max(frame_gap(&frame_at(&imported, "hand", &at), &hand));
        // Not the other order: R(axis2, q2) R(axis, q1) is another frame.
        let swapped = mat_mul(&rot(x, u2), &rot(z, u1));
        assert!(frame_gap(&frame_at(&imported, "arm", &at), &(arm.0, swapped)) > 1e-2);
    }
    println!("universal/revolute2 frames against the oracle: worst {worst:e}");
    assert!(worst < 1e-14, "worst {worst:e}");
    let kernels = worst_difference(&plain, &imported);
    println!("ujoint from SDF vs ujoint.toml: worst relative difference {kernels:e}");
    assert!(kernels < 1e-12, "worst {kernels:e}");
}

/// SDF `screw` joints are one coordinate, the angle `q` about `<axis>`, with the translation along
/// it: `<screw_thread_pitch>` p (SDF 1.10, m per revolution, positive right-handed) moves `p q /
/// (2 pi)`, the deprecated `<thread_pitch>` t (rad/m, positive left-handed) `-q / t`. Each nut's
/// frame relative to its parent is the rotation about the axis and `offset + lead(q) axis`,
/// computed here; the imported robot derives the kernels of screw.toml, written by hand.
#[test]
fn sdf_screw_joints_turn_and_advance_by_the_pitch() {
    let imported = model_at(&here().join("screw_sdf.toml"));
    let plain = model_at(&here().join("screw.toml"));
    assert_eq!(imported.actuated, [0, 1, 2]);
    let s2 = std::f64::consts::FRAC_1_SQRT_2;
    let tau = 2.0 * std::f64::consts::PI;
    // (body, parent, axis in the parent's axes, offset, the lead per rad)
    type Screw<'a> = (&'a str, Option<&'a str>, [f64; 3], [f64; 3], f64);
    let joints: [Screw<'_>; 3] = [
        ("nut", None, [0.0, 0.0, 1.0], [0.0, 0.0, 0.2], 0.005 / tau),
        (
            "nut2",
            Some("nut"),
            [0.0, -1.0, 0.0],
            [0.1, 0.0, 0.0],
            1.0 / 200.0,
        ),
        (
            "nut3",
            Some("nut2"),
            [s2, s2, 0.0],
            [0.0, 0.0, 0.1],
            -0.01 / tau,
        ),
    ];
    let mut worst = 0.0f64;
    for q in [[0.8, -1.7, 2.2], [-3.0, 0.4, -0.9]] {
        let at = [("lead", q[0]), ("old", q[1]), ("slant", q[2])];
        for (k, (body, parent, axis, offset, per_rad)) in joints.iter().enumerate() {
            let (pc, rc) = frame_at(&imported, body, &at);
            let (pp, rp) = match parent {
                Some(p) => frame_at(&imported, p, &at),
                None => ([0.0; 3], rot([0.0, 0.0, 1.0], 0.0)),
            };
            // The child in the parent's axes.
            let rpt: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| rp[j][i]));
            let rel_p = mat_vec(&rpt, [pc[0] - pp[0], pc[1] - pp[1], pc[2] - pp[2]]);
            let rel_r = mat_mul(&rpt, &rc);
            let want_p: [f64; 3] = std::array::from_fn(|i| offset[i] + per_rad * q[k] * axis[i]);
            worst = worst.max(frame_gap(&(rel_p, rel_r), &(want_p, rot(*axis, q[k]))));
        }
    }
    println!("screw frames against the oracle: worst {worst:e}");
    assert!(worst < 1e-14, "worst {worst:e}");
    let kernels = worst_difference(&plain, &imported);
    println!("screw from SDF vs screw.toml: worst relative difference {kernels:e}");
    assert!(kernels < 1e-12, "worst {kernels:e}");
}

/// A universal joint that closes a loop (no loop kind is a universal joint) brings its child in,
/// and the joint that brought the child in (the ball `b2`) closes the loop instead, as for a
/// prismatic joint; a note says so. uloop.sdf: a crank on a ball joint at the origin, its tip
/// (0.2, 0, 0) the ball `b2` to a rod that hangs from the world by the universal joint `u` at
/// (0.2, 0, 0.3). The loop's `f` is the crank's tip less the rod's end, both computed here:
/// `Rx Ry Rz (0.2, 0, 0)` and `(0.2, 0, 0.3) + Rz(u_1) Ry(u_2) (0, 0, -0.3)`.
#[test]
fn sdf_universal_joint_closing_a_loop_is_in_the_tree() {
    use rbss_codegen::import::{Format, import_file};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let inertial = UNIT_INERTIAL;
    std::fs::write(
        d.join("uloop.sdf"),
        format!(
            "<sdf version=\"1.9\"><model name=\"uloop\">\
             <link name=\"crank\">{inertial}</link>\
             <link name=\"rod\"><pose>0.2 0 0 0 0 0</pose>{inertial}</link>\
             <joint name=\"r\" type=\"ball\"><parent>world</parent><child>crank</child></joint>\
             <joint name=\"b2\" type=\"ball\"><parent>crank</parent><child>rod</child></joint>\
             <joint name=\"u\" type=\"universal\"><parent>world</parent><child>rod</child>\
             <pose>0 0 0.3 0 0 0</pose>\
             <axis><xyz>0 0 1</xyz></axis><axis2><xyz>0 1 0</xyz></axis2></joint>\
             </model></sdf>"
        ),
    )
    .unwrap();
    let (imp, _) = import_file(&d.join("uloop.sdf"), "uloop.sdf", Format::Sdf)
        .unwrap_or_else(|e| panic!("{}", e.render()));
    let coords: Vec<&str> = imp.coordinates.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(coords, ["r_x", "r_y", "r_z", "u_1", "u_2"]);
    assert_eq!(imp.loops.len(), 1);
    assert_eq!(imp.loops[0].keys[0], ("name", "\"b2\"".to_string()));
    assert_eq!(imp.loops[0].keys[1], ("kind", "\"ball\"".to_string()));
    assert!(
        imp.notes
            .iter()
            .any(|n| n.contains("universal joint `u`") && n.contains("`b2`")),
        "{:?}",
        imp.notes
    );
    std::fs::write(d.join("m.toml"), "sdf = \"uloop.sdf\"\n").unwrap();
    let m = model_at(&d.join("m.toml"));
    let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    let mut worst = 0.0f64;
    for q in [
        [0.0; 5],
        [0.3, -0.2, 0.9, 0.4, -0.3],
        [-1.2, 0.7, -2.0, 2.1, 0.9],
    ] {
        let at = [
            ("r_x", q[0]),
            ("r_y", q[1]),
            ("r_z", q[2]),
            ("u_1", q[3]),
            ("u_2", q[4]),
        ];
        let f = f_at(&m, &at);
        let rc = mat_mul(&rot(x, q[0]), &mat_mul(&rot(y, q[1]), &rot(z, q[2])));
        let tip = mat_vec(&rc, [0.2, 0.0, 0.0]);
        let hang = mat_vec(&mat_mul(&rot(z, q[3]), &rot(y, q[4])), [0.0, 0.0, -0.3]);
        let end = [0.2 + hang[0], hang[1], 0.3 + hang[2]];
        assert_eq!(f.len(), 3);
        for k in 0..3 {
            worst = worst.max((f[k] - (tip[k] - end[k])).abs());
        }
    }
    println!("universal loop: f against the oracle, worst {worst:e}");
    assert!(worst < 1e-15, "worst {worst:e}");
}

/// `[[f64; 3]; 3]` and a position: a rigid transform, `a * b`.
fn compose(
    a: &([f64; 3], [[f64; 3]; 3]),
    b: &([f64; 3], [[f64; 3]; 3]),
) -> ([f64; 3], [[f64; 3]; 3]) {
    let d = mat_vec(&a.1, b.0);
    (
        [a.0[0] + d[0], a.0[1] + d[1], a.0[2] + d[2]],
        mat_mul(&a.1, &b.1),
    )
}

/// Nested models (SDFormat 1.8): a `<model>` inside the model is a scope, its links and joints
/// named `arm::upper` from outside it (bodies `arm__upper`, coordinates `arm__elbow`) and
/// `upper` inside it; its `<pose>` is relative to the model around it (or `relative_to` a frame
/// of that scope), and `__model__` inside it is its own frame. Two levels here: `arm` in the
/// robot, `hand` in `arm`, placed relative to `lower` (a name of arm's scope), the palm relative
/// to hand's `__model__`; a joint of the outer model reaches `arm::upper`, one of `arm` reaches
/// `hand::palm`. Every link's world frame is the product of the poses, computed here, at zero
/// and with the joints turned.
#[test]
fn sdf_nested_models_are_scopes() {
    use rbss_codegen::import::{Format, import_file};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let inertial = UNIT_INERTIAL;
    std::fs::write(
        d.join("nested.sdf"),
        format!(
            "<sdf version=\"1.9\"><model name=\"robot\">\
             <link name=\"base\">{inertial}</link>\
             <joint name=\"fix\" type=\"fixed\"><parent>world</parent><child>base</child></joint>\
             <model name=\"arm\"><pose>0.1 0 0.2 0 0 0.5</pose>\
               <link name=\"upper\"><pose>0 0 0.1 0 0 0</pose>{inertial}</link>\
               <link name=\"lower\"><pose relative_to=\"upper\">0.3 0 0 0 0 0</pose>{inertial}</link>\
               <joint name=\"elbow\" type=\"revolute\"><parent>upper</parent><child>lower</child>\
               <axis><xyz>0 1 0</xyz></axis></joint>\
               <model name=\"hand\"><pose relative_to=\"lower\">0.2 0 0 0.4 0 0</pose>\
                 <link name=\"palm\"><pose relative_to=\"__model__\">0 0.05 0 0 0 0</pose>{inertial}</link>\
               </model>\
               <joint name=\"wrist\" type=\"revolute\"><parent>lower</parent><child>hand::palm</child>\
               <axis><xyz expressed_in=\"__model__\">1 0 0</xyz></axis></joint>\
             </model>\
             <joint name=\"shoulder\" type=\"revolute\"><parent>base</parent><child>arm::upper</child>\
             <axis><xyz>0 0 1</xyz></axis></joint>\
             </model></sdf>"
        ),
    )
    .unwrap();
    let (imp, _) = import_file(&d.join("nested.sdf"), "nested.sdf", Format::Sdf)
        .unwrap_or_else(|e| panic!("{}", e.render()));
    let bodies: Vec<&str> = imp.bodies.iter().map(|b| b.name.as_str()).collect();
    assert_eq!(
        bodies,
        ["base", "arm__upper", "arm__lower", "arm__hand__palm"]
    );
    let coords: Vec<&str> = imp.coordinates.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(coords, ["shoulder", "arm__elbow", "arm__wrist"]);
    std::fs::write(d.join("m.toml"), "sdf = \"nested.sdf\"\n").unwrap();
    let m = model_at(&d.join("m.toml"));
    let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    let t = |p: [f64; 3]| (p, rot(z, 0.0));
    let mut worst = 0.0f64;
    for (s, e, w) in [(0.0, 0.0, 0.0), (0.7, -1.1, 0.4), (-2.0, 0.5, 2.9)] {
        let at = [("shoulder", s), ("arm__elbow", e), ("arm__wrist", w)];
        let arm = ([0.1, 0.0, 0.2], rot(z, 0.5));
        let upper = compose(&compose(&arm, &t([0.0, 0.0, 0.1])), &([0.0; 3], rot(z, s)));
        let lower = compose(
            &compose(&upper, &t([0.3, 0.0, 0.0])),
            &([0.0; 3], rot(y, e)),
        );
        let hand = compose(&lower, &([0.2, 0.0, 0.0], rot(x, 0.4)));
        // The wrist's axis: x of arm's frame, in the palm's axes at zero (hand turned 0.4
        // about x of lower, lower's axes arm's): still x.
        let palm = compose(
            &compose(&hand, &t([0.0, 0.05, 0.0])),
            &([0.0; 3], rot(x, w)),
        );
        for (name, want) in [
            ("arm__upper", upper),
            ("arm__lower", lower),
            ("arm__hand__palm", palm),
        ] {
            worst = worst.max(frame_gap(&frame_at(&m, name, &at), &want));
        }
    }
    println!("nested models: link frames against the oracle, worst {worst:e}");
    assert!(worst < 1e-14, "worst {worst:e}");
}

/// `<include>`: the included file's `<model>` in the `<include>`'s place, a nested model named by
/// `<include><name>` (else its own name) and placed by `<include><pose>` (else its own). One
/// arm file included twice (a relative path and `file://`), as `left` and `right`; a gripper by
/// `model://gripper`, found in the source's directory through its `model.config`. Every link's
/// world frame is the product of the poses, computed here; the source's hash covers the included
/// files (an edit of the arm's file changes it).
#[test]
fn sdf_includes_are_nested_models() {
    use rbss_codegen::import::{Format, import_file};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let inertial = UNIT_INERTIAL;
    std::fs::create_dir_all(d.join("parts")).unwrap();
    std::fs::create_dir_all(d.join("gripper")).unwrap();
    let arm = format!(
        "<sdf version=\"1.9\"><model name=\"arm\">\
         <link name=\"upper\"><pose>0 0 0.1 0 0 0</pose>{inertial}</link>\
         <link name=\"lower\"><pose relative_to=\"upper\">0.3 0 0 0 0 0</pose>{inertial}</link>\
         <joint name=\"elbow\" type=\"revolute\"><parent>upper</parent><child>lower</child>\
         <axis><xyz>0 1 0</xyz></axis></joint></model></sdf>"
    );
    std::fs::write(d.join("parts/arm.sdf"), &arm).unwrap();
    std::fs::write(
        d.join("gripper/model.config"),
        "<?xml version=\"1.0\"?><model><name>gripper</name><sdf version=\"1.9\">g.sdf</sdf></model>",
    )
    .unwrap();
    std::fs::write(
        d.join("gripper/g.sdf"),
        format!(
            "<sdf version=\"1.9\"><model name=\"gripper\"><pose>0.5 0 0.3 0 0 0</pose>\
             <link name=\"finger\">{inertial}</link></model></sdf>"
        ),
    )
    .unwrap();
    let abs = d.join("parts/arm.sdf").display().to_string();
    std::fs::write(
        d.join("robot.sdf"),
        format!(
            "<sdf version=\"1.9\"><model name=\"robot\">\
             <link name=\"base\">{inertial}</link>\
             <joint name=\"fix\" type=\"fixed\"><parent>world</parent><child>base</child></joint>\
             <include><uri>parts/arm.sdf</uri><name>left</name><pose>0 0.2 0 0 0 0</pose></include>\
             <include><uri>file://{abs}</uri><name>right</name><pose>0 -0.2 0 0 0 0</pose></include>\
             <include><uri>model://gripper</uri></include>\
             <joint name=\"shoulder_l\" type=\"revolute\"><parent>base</parent><child>left::upper</child>\
             <axis><xyz>0 0 1</xyz></axis></joint>\
             <joint name=\"shoulder_r\" type=\"revolute\"><parent>base</parent><child>right::upper</child>\
             <axis><xyz>0 0 1</xyz></axis></joint>\
             <joint name=\"grip\" type=\"fixed\"><parent>left::lower</parent><child>gripper::finger</child></joint>\
             </model></sdf>"
        ),
    )
    .unwrap();
    let (imp, _) = import_file(&d.join("robot.sdf"), "robot.sdf", Format::Sdf)
        .unwrap_or_else(|e| panic!("{}", e.render()));
    let mut bodies: Vec<&str> = imp.bodies.iter().map(|b| b.name.as_str()).collect();
    bodies.sort();
    assert_eq!(
        bodies,
        [
            "base",
            "gripper__finger",
            "left__lower",
            "left__upper",
            "right__lower",
            "right__upper"
        ]
    );
    let hash = imp.source.as_ref().unwrap().sha256.clone();
    std::fs::write(d.join("m.toml"), "sdf = \"robot.sdf\"\n").unwrap();
    let m = model_at(&d.join("m.toml"));
    let (y, z) = ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    let t = |p: [f64; 3]| (p, rot(z, 0.0));
    let mut worst = 0.0f64;
    for q in [[0.0; 4], [0.7, -1.1, 0.4, 2.0], [-2.0, 0.5, 2.9, -0.3]] {
        let at = [
            ("shoulder_l", q[0]),
            ("left__elbow", q[1]),
            ("shoulder_r", q[2]),
            ("right__elbow", q[3]),
        ];
        let mut want = Vec::new();
        for (side, at_y, s, e) in [("left", 0.2, q[0], q[1]), ("right", -0.2, q[2], q[3])] {
            let upper = compose(&t([0.0, at_y, 0.1]), &([0.0; 3], rot(z, s)));
            let lower = compose(
                &compose(&upper, &t([0.3, 0.0, 0.0])),
                &([0.0; 3], rot(y, e)),
            );
            if side == "left" {
                // The finger at (0.5, 0, 0.3) as written, carried by the left lower arm from
                // its place at zero, (0.3, 0.2, 0.1).
                let finger = compose(&lower, &t([0.2, -0.2, 0.2]));
                want.push(("gripper__finger".to_string(), finger));
            }
            want.push((format!("{side}__upper"), upper));
            want.push((format!("{side}__lower"), lower));
        }
        for (name, w) in &want {
            worst = worst.max(frame_gap(&frame_at(&m, name, &at), w));
        }
    }
    println!("included models: link frames against the oracle, worst {worst:e}");
    assert!(worst < 1e-14, "worst {worst:e}");

    std::fs::write(
        d.join("parts/arm.sdf"),
        arm.replace("0.3 0 0 0 0 0", "0.35 0 0 0 0 0"),
    )
    .unwrap();
    let (edited, _) = import_file(&d.join("robot.sdf"), "robot.sdf", Format::Sdf)
        .unwrap_or_else(|e| panic!("{}", e.render()));
    assert_ne!(edited.source.unwrap().sha256, hash);
    assert_eq!(
        rbss_codegen::import::sdf_included_files(
            &d.join("robot.sdf"),
            &std::fs::read_to_string(d.join("robot.sdf")).unwrap()
        )
        .len(),
        3
    );

    // A `model://` that resolves nowhere: one error at the `<uri>`, naming where it looked.
    std::fs::write(
        d.join("lost.sdf"),
        "<sdf version=\"1.9\"><model name=\"lost\"><link name=\"a\"/>\
         <include><uri>model://nowhere_to_be_found</uri></include></model></sdf>",
    )
    .unwrap();
    let err = import_file(&d.join("lost.sdf"), "lost.sdf", Format::Sdf).unwrap_err();
    let text = err.render();
    assert!(
        text.contains("cannot resolve `model://nowhere_to_be_found`")
            && text.contains("nowhere_to_be_found")
            && text.contains("GZ_SIM_RESOURCE_PATH"),
        "{text}"
    );
}

/// SDF 1.6's `<axis><use_parent_model_frame>true` (removed in 1.7, whose converter writes
/// `expressed_in="__model__"` for it): the axis in the model's frame. ujoint.sdf with the hand
/// turned 0.5 rad about z (so that the joint's frame is not the model's) and `<axis2>`'s x given
/// by the flag derives the kernels of the same file with `expressed_in="__model__"`, and
/// differs from the one without either (x of the joint's frame).
#[test]
fn sdf_use_parent_model_frame_is_the_models_frame() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(here().join("ujoint.sdf"))
        .unwrap()
        .replace(
            "<pose relative_to=\"arm\">0 0 0.4 0 0 0</pose>",
            "<pose relative_to=\"arm\">0 0 0.4 0 0 0.5</pose>",
        );
    let axis2 = "<axis2><xyz expressed_in=\"__model__\">1 0 0</xyz></axis2>";
    assert!(text.contains(axis2) && text.contains("0 0 0.4 0 0 0.5"));
    let model = |name: &str, axis: &str| {
        let sdf = text.replace(axis2, axis);
        std::fs::write(dir.path().join(format!("{name}.sdf")), sdf).unwrap();
        let toml = dir.path().join(format!("{name}.toml"));
        std::fs::write(&toml, format!("sdf = \"{name}.sdf\"\n")).unwrap();
        model_at(&toml)
    };
    let expressed = model("expressed", axis2);
    let flag = model(
        "flag",
        "<axis2><xyz>1 0 0</xyz><use_parent_model_frame>true</use_parent_model_frame></axis2>",
    );
    let joint = model("joint", "<axis2><xyz>1 0 0</xyz></axis2>");
    let same = worst_difference(&expressed, &flag);
    let other = worst_difference(&expressed, &joint);
    println!("use_parent_model_frame vs expressed_in=__model__ {same:e}; the joint's x {other:e}");
    assert!(same < 1e-12, "{same:e}");
    assert!(other > 1e-3, "{other:e}");
}
