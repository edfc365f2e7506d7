//! No import circles between the top-level modules of the workspace's crates: each crate's
//! modules form layers (docs/src/architecture.md, "Layers"), and a reference from a lower
//! module to a higher one fails here with every circle and the place of each of its edges.

use std::path::Path;

use rovib_testkit::module_graph::ModuleGraph;

/// Circles known and not yet broken, each with its reason: (crate folder, its modules sorted).
const ALLOWED: &[(&str, &[&str])] = &[];

/// Each crate's source folder (relative to the workspace) and what in it belongs to another
/// crate root (the `rovib` binary: `main.rs` and its `cli` modules).
const CRATES: &[(&str, &[&str])] =
    &[("src", &["main.rs", "cli"]), ("runtime/src", &[]), ("codegen/src", &[]), ("base/src", &[])];

#[test]
fn no_import_circles() {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let mut report = String::new();
    for (folder, skip) in CRATES {
        let graph = ModuleGraph::read(&workspace.join(folder), skip).unwrap();
        assert!(graph.modules.len() > 3, "{folder}: found only {:?}", graph.modules);
        for cycle in graph.cycles() {
            let allowed =
                ALLOWED.iter().any(|(f, m)| f == folder && m.iter().copied().eq(cycle.iter().map(String::as_str)));
            if !allowed {
                report.push_str(&format!("{folder}: {}\n", cycle.join(", ")));
                report.push_str(&graph.describe(&cycle));
            }
        }
    }
    assert!(report.is_empty(), "import circles between top-level modules:\n{report}");
}
