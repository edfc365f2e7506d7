//! Criterion benchmarks of code generation: `rovib_codegen::generate_molecule(path, text)` for
//! every `molecules/*.toml` of the workspace (read once, at startup), as `codegen/NAME`.

use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};

fn codegen_per_molecule(c: &mut Criterion) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../molecules");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()))
        .map(|entry| entry.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no molecule definitions in {}", dir.display());
    for file in files {
        let stem = file.file_stem().and_then(|s| s.to_str()).expect("UTF-8 file name").to_owned();
        let path = format!("molecules/{stem}.toml");
        let text = std::fs::read_to_string(&file).unwrap_or_else(|e| panic!("reading {}: {e}", file.display()));
        // Fail early and readably if a definition does not generate.
        rovib_codegen::generate_molecule(&path, &text).unwrap_or_else(|e| panic!("{}", e[0]));
        c.bench_function(&format!("codegen/{stem}"), |b| {
            b.iter(|| rovib_codegen::generate_molecule(black_box(&path), black_box(&text)).unwrap())
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3));
    targets = codegen_per_molecule
}
criterion_main!(benches);
