//! Sums over index ranges with coefficient arrays, inline or from a CSV file beside the
//! definition: equal to the sum written out, with located errors (file and line) for bad data,
//! and a 10⁴-term fit generated on a build script's stack.

mod common;

use common::method;

use rovib_codegen::{DefinitionError, generate_molecule};

const FIT: &str = include_str!("fixtures/sums/fit.toml");
const FIT_PATH: &str = "tests/fixtures/sums/fit.toml";

fn errors(path: &str, text: &str) -> Vec<DefinitionError> {
    match generate_molecule(path, text) {
        Ok(_) => panic!("expected errors"),
        Err(e) => e,
    }
}

/// The fit from the CSV file equals the same sum written out with the numbers of the file.
#[test]
fn a_sum_over_a_csv_table_equals_the_sum_written_out() {
    let m = generate_molecule(FIT_PATH, FIT).expect("valid");
    assert_eq!(m.data_files.len(), 1);
    assert!(m.data_files[0].ends_with("fit.csv"));
    let v = [-1.5e-3, 2.0e-4, -7.5e-4, 1.0e-4, -2.5e-5, 1.0e-5];
    let terms: Vec<String> = v.iter().enumerate().map(|(l, c)| format!("{c:e} * legendre({l}, cos(theta))")).collect();
    let written =
        FIT.replace("sum(l, 0, 5, v[l] * legendre(l, cos(theta)))", &format!("({})", terms.join(" + "))).replace(
            "sum(k, 0, 2, w[k] * pow(R - 7, k + 2))",
            "(0.5 * pow(R - 7, 2) - 0.25 * pow(R - 7, 3) + 0.125 * pow(R - 7, 4))",
        );
    assert!(!written.contains("sum("));
    let w = generate_molecule(FIT_PATH, &written).expect("valid");
    for i in 0..20 {
        let t = f64::from(i) / 20.0;
        let q = [2.0 + 0.4 * t, 5.0 + 4.0 * ((3.0 * t) % 1.0), 0.1 + 2.9 * ((7.0 * t) % 1.0)];
        for (name, n) in [("potential", 0), ("potential_gradient", 3)] {
            let (a_out, a) = common::interpret(&method(&m.source, name), &q, n);
            let (b_out, b) = common::interpret(&method(&w.source, name), &q, n);
            let (a, b) = (a.expect("U"), b.expect("U"));
            assert!((a - b).abs() <= 1e-15 * (1.0 + a.abs()), "{name} at {q:?}: {a} vs {b}");
            for (x, y) in a_out.iter().zip(&b_out) {
                assert!((x - y).abs() <= 1e-14 * (1e-3 + x.abs()), "{name} at {q:?}: {x} vs {y}");
            }
        }
    }
}

#[test]
fn bad_sums_and_arrays_are_located_errors() {
    let e = &errors(FIT_PATH, &FIT.replace("sum(l, 0, 5, v[l]", "sum(l, 0, 6, v[l]"))[0];
    assert_eq!(e.message, "index 6 is outside `v` (6 values) in the potential");
    assert_eq!((e.line, e.column), (39, 16), "{e}");
    let e = &errors(FIT_PATH, &FIT.replace("sum(l, 0, 5,", "sum(l, 0, r,"))[0];
    assert_eq!(e.message, "the bounds of `sum` are not integer constants in the potential");
    let e = &errors(FIT_PATH, &FIT.replace("sum(l, 0, 5,", "sum(l, 5, 0,"))[0];
    assert!(e.message.starts_with("`sum` from 5 to 0 has"), "{e}");
    let e = &errors(FIT_PATH, &FIT.replace("sum(l, 0, 5,", "sum(r, 0, 5,"))[0];
    assert_eq!(e.message, "the first argument of `sum` is not a new index name in the potential");
    let e = &errors(FIT_PATH, &FIT.replace("w[k]", "u[k]"))[0];
    assert_eq!(e.message, "`u` is not an array in the potential");
    assert!(e.help.contains("the arrays are: v, w"), "{e}");
    let e = &errors(FIT_PATH, &FIT.replace("w[k]", "w[k + 0.5]"))[0];
    assert_eq!(e.message, "the index of `w` is not an integer constant in the potential");
    let e = &errors(FIT_PATH, &FIT.replace("\"fit.csv\"", "\"missing.csv\""))[0];
    assert!(e.message.starts_with("cannot read `tests/fixtures/sums/missing.csv`"), "{e}");
    assert_eq!((e.path.as_str(), e.line), (FIT_PATH, 5));
    let e = &errors(FIT_PATH, &FIT.replace("column = 2", "column = 3"))[0];
    assert_eq!(e.message, "this line has 2 column(s), not column 3");
    assert_eq!((e.path.as_str(), e.line, e.column), ("tests/fixtures/sums/fit.csv", 2, 1));
    let e = &errors(FIT_PATH, &FIT.replace("w = [0.5, -0.25, 0.125]", "w = []"))[0];
    assert_eq!(e.message, "array `w` is empty");
    let e = &errors(FIT_PATH, &FIT.replace("w = [0.5", "sum = [0.5"))[0];
    assert!(e.message.contains("the array name `sum` is reserved"), "{e}");
}

/// A CSV value that is not a number: the error names the CSV file, its line and column.
#[test]
fn a_bad_csv_value_is_located_in_the_csv_file() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("sums_bad_csv");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("fit.csv"), "# l, V\n0, 1e-3\n1, 2.0e-4x\n").unwrap();
    let path = dir.join("fit.toml");
    let all = errors(path.to_str().unwrap(), FIT);
    let csv = dir.join("fit.csv").display().to_string();
    assert_eq!(all[0].message, "`2.0e-4x` is not a finite number");
    assert_eq!((all[0].path.as_str(), all[0].line, all[0].column), (csv.as_str(), 3, 4), "{}", all[0]);
    assert_eq!(all.len(), 1, "uses of the broken array are not errors of their own: {all:#?}");
}

/// A fit of 10⁴ terms, Legendre polynomials in cos θ times powers of R − 7 with coefficients
/// from a 10⁴-line CSV file, is one line of the definition: generated on a build script's
/// 2 MiB stack, its potential equals the double sum evaluated directly. Prints the size.
#[test]
fn ten_thousand_term_fit_from_a_table() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("sums_big");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let coefficient = |l: usize, j: usize| {
        ((l * 7 + j * 13) % 17) as f64 * 1e-4 * 0.5f64.powi(j as i32) - 8e-4 * 0.5f64.powi(j as i32)
    };
    let csv: String = (0..10_000).map(|n| format!("{n}, {:e}\n", coefficient(n / 100, n % 100))).collect();
    std::fs::write(dir.join("big.csv"), csv).unwrap();
    let text = FIT
        .replace("name = \"fit\"", "name = \"big\"")
        .replace("{ file = \"fit.csv\", column = 2 }", "{ file = \"big.csv\", column = 2 }")
        .replace(
            "sum(l, 0, 5, v[l] * legendre(l, cos(theta))) * exp(-(R - 7))",
            "sum(l, 0, 99, legendre(l, cos(theta)) * sum(j, 0, 99, v[100 * l + j] * pow(R - 7, j)))",
        );
    let path = dir.join("big.toml").to_str().unwrap().to_owned();
    let m = std::thread::Builder::new()
        .stack_size(2 << 20)
        .spawn(move || generate_molecule(&path, &text))
        .unwrap()
        .join()
        .expect("no stack overflow")
        .expect("valid");
    println!("10^4-term fit: {} lines, {} operations, generated in {:.2?}", m.lines(), m.operations(), m.codegen_time);
    let potential = method(&m.source, "potential");
    for &(r, big_r, theta) in &[(2.2, 7.3, 0.4), (2.1, 6.8, 2.0), (2.3, 7.05, 1.3)] {
        let u = common::interpret(&potential, &[r, big_r, theta], 0).1.expect("U");
        let x: f64 = f64::cos(theta);
        let mut p = vec![1.0, x];
        for n in 1..99 {
            let n_f = n as f64;
            p.push(((2.0 * n_f + 1.0) * x * p[n] - n_f * p[n - 1]) / (n_f + 1.0));
        }
        let (mut fit, mut scale) = (0.0, 0.0);
        for (l, p_l) in p.iter().enumerate() {
            for j in 0..100 {
                let t = coefficient(l, j) * p_l * (big_r - 7.0).powi(j as i32);
                fit += t;
                scale += t.abs();
            }
        }
        let rest = 0.4 * (r - 2.2f64).powi(2)
            + (0.5 * (big_r - 7.0f64).powi(2) - 0.25 * (big_r - 7.0f64).powi(3) + 0.125 * (big_r - 7.0f64).powi(4))
                * 1e-3;
        let want = fit + rest;
        assert!((u - want).abs() <= 1e-13 * (scale + rest.abs()), "at {r}, {big_r}, {theta}: {u} vs {want}");
    }
}
