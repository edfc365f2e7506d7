//! A registry made from the files of a folder: every `NAME.rs` of the folder (other than
//! `mod.rs`) becomes a module, and one constant of each is listed in a slice, in the order of the
//! files' names. The root crate's build script makes `src/report/`'s outputs this way, so that
//! adding an output is adding its file (`src/report/mod.rs` includes the generated text).

use std::path::Path;

/// What a folder registers: the constant each file declares, its type and the slice listing them.
#[derive(Clone, Copy, Debug)]
pub struct Registry<'a> {
    /// The folder as the messages name it (`src/report/`).
    pub folder: &'a str,
    /// The constant every file declares (`OUTPUT`).
    pub constant: &'a str,
    /// Its type (`Output`), in scope where the text is included.
    pub ty: &'a str,
    /// The slice of them the text defines (`OUTPUTS`).
    pub list: &'a str,
    /// A file to imitate, for the messages (`src/report/dipole_csv.rs`).
    pub example: &'a str,
}

/// The modules of `dir`: every `NAME.rs` file but `mod.rs`, `(NAME, absolute path)`, in the
/// order of the names. Fails with the file and what to change for a name that is not in snake
/// case (lower-case letters, digits and single underscores, starting with a letter), which the
/// generated code needs as a module name (and, CamelCased, as a type name).
pub fn folder_modules(dir: &Path, folder: &str) -> Result<Vec<(String, String)>, String> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("cannot read {}: {e}", dir.display()))?;
    let mut modules = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| format!("cannot read {}: {e}", dir.display()))?.path();
        let Some(stem) = path.file_name().and_then(|n| n.to_str()).and_then(|n| n.strip_suffix(".rs")) else {
            continue;
        };
        if stem == "mod" || !path.is_file() {
            continue;
        }
        let snake = stem.starts_with(|c: char| c.is_ascii_lowercase())
            && stem
                .split('_')
                .all(|w| !w.is_empty() && w.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit()));
        if !snake {
            return Err(format!(
                "{}: every file of {folder} is a module, and `{stem}` is not a module name; rename it in snake case \
                 (lower-case letters, digits and single underscores, starting with a letter), e.g. energy_csv.rs",
                path.display()
            ));
        }
        let path = path.to_str().ok_or_else(|| format!("{}: the path is not UTF-8", path.display()))?.to_owned();
        modules.push((stem.to_owned(), path));
    }
    modules.sort();
    Ok(modules)
}

/// The Rust text declaring the modules of `dir` ([`folder_modules`], by absolute `#[path]`, so
/// the text can be included from anywhere) and the slice of their constants; headed
/// `@generated`. Fails with the file and what to change for a file whose name is not a module
/// name or that does not declare the constant.
pub fn folder_registry(dir: &Path, r: &Registry<'_>) -> Result<String, String> {
    let modules = folder_modules(dir, r.folder)?;
    for (_, path) in &modules {
        let text = std::fs::read_to_string(path).map_err(|e| format!("cannot read {path}: {e}"))?;
        if !text.contains(&format!("const {}: {}", r.constant, r.ty)) {
            return Err(format!(
                "{path}: every file of {} declares `pub(super) const {}: {} = ...;` (see {}); add it, or move the \
                 file out of {}",
                r.folder, r.constant, r.ty, r.example, r.folder
            ));
        }
    }
    let mut source = format!(
        "// @generated from the files of {}: one module per file, in the order of the files' names.\n\
         // Do not edit; add a file to {} instead.\n\n",
        r.folder, r.folder
    );
    for (name, path) in &modules {
        source.push_str(&format!("#[path = {path:?}]\nmod {name};\n"));
    }
    source.push_str(&format!(
        "\n/// The `{}` of every file of {}, in the order of the files' names.\npub const {}: &[{}] = &[\n",
        r.constant, r.folder, r.list, r.ty
    ));
    for (name, _) in &modules {
        source.push_str(&format!("    {name}::{},\n", r.constant));
    }
    source.push_str("];\n");
    Ok(source)
}

#[cfg(test)]
mod tests {
    use super::*;

    const OUTPUTS: Registry<'static> = Registry {
        folder: "src/report/",
        constant: "OUTPUT",
        ty: "Output",
        list: "OUTPUTS",
        example: "src/report/dipole_csv.rs",
    };

    fn folder(name: &str, files: &[(&str, &str)]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("rovib-folder-registry-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for (file, text) in files {
            std::fs::write(dir.join(file), text).unwrap();
        }
        dir
    }

    #[test]
    fn every_file_but_mod_rs_is_a_module_in_the_order_of_the_names() {
        let c = "pub(super) const OUTPUT: Output = x;";
        let dir = folder("order", &[("zeta.rs", c), ("mod.rs", ""), ("alpha_2.rs", c), ("notes.txt", "")]);
        let text = folder_registry(&dir, &OUTPUTS).unwrap();
        assert!(text.starts_with("// @generated"), "{text}");
        let alpha = text.find("mod alpha_2;").unwrap();
        let zeta = text.find("mod zeta;").unwrap();
        assert!(alpha < zeta, "{text}");
        assert!(
            text.contains("pub const OUTPUTS: &[Output] = &[\n    alpha_2::OUTPUT,\n    zeta::OUTPUT,\n];"),
            "{text}"
        );
        assert!(!text.contains("mod mod") && !text.contains("notes"), "{text}");
        assert!(text.contains(&format!("#[path = {:?}]", dir.join("zeta.rs").to_str().unwrap())), "{text}");
        // Deterministic: the same text again.
        assert_eq!(folder_registry(&dir, &OUTPUTS).unwrap(), text);
    }

    #[test]
    fn a_file_without_the_constant_or_with_a_bad_name_is_refused_with_what_to_change() {
        let dir = folder("missing", &[("energy_csv.rs", "pub fn f() {}")]);
        let e = folder_registry(&dir, &OUTPUTS).unwrap_err();
        assert!(e.contains("energy_csv.rs") && e.contains("pub(super) const OUTPUT: Output"), "{e}");
        let dir = folder("name", &[("Energy-csv.rs", "pub(super) const OUTPUT: Output = x;")]);
        let e = folder_registry(&dir, &OUTPUTS).unwrap_err();
        assert!(e.contains("`Energy-csv` is not a module name"), "{e}");
        for bad in ["double__underscore.rs", "_leading.rs", "trailing_.rs", "2d.rs"] {
            let dir = folder("snake", &[(bad, "pub(super) const OUTPUT: Output = x;")]);
            let e = folder_registry(&dir, &OUTPUTS).unwrap_err();
            assert!(e.contains("is not a module name"), "{bad}: {e}");
        }
    }
}
