//! A scene's `[potential] gradient`: how ∂U/∂q of a `library` surface is taken. `"analytic"`
//! (the default) calls the library's `rovib_surface_gradient`; `"central-differences"` takes
//! central differences of its energy ([`crate::runtime::finite_differences`]), for a library
//! that has no gradient function (which is refused without this key, so that the cost is
//! chosen knowingly) or to measure what an analytic gradient gains. The run's summary states
//! the cost and the accuracy.

use crate::runtime::diagnostic::{FileError, Source};
use toml::Spanned;

/// Whether the scene asks for central differences; an error at the key for an unknown value
/// or for the key without `library` (a definition's potential has its exact gradient).
pub fn scene_gradient(
    src: &Source<'_>,
    gradient: Option<&Spanned<String>>,
    library: Option<&Spanned<String>>,
) -> Result<bool, FileError> {
    let Some(gradient) = gradient else { return Ok(false) };
    let differences = match gradient.get_ref().as_str() {
        "analytic" => false,
        "central-differences" => true,
        other => {
            return Err(src.error(
                gradient.span(),
                format!("`potential.gradient = {other:?}` is not a way rovib takes gradients"),
                "write \"analytic\" (the library's rovib_surface_gradient, the default) or \"central-differences\"",
            ));
        }
    };
    if library.is_none() {
        return Err(src.error(
            gradient.span(),
            "`potential.gradient` applies to a `library` surface; the definition's potential has its exact gradient",
            "add `library = \"libsurf.so\"`, or remove `gradient`",
        ));
    }
    Ok(differences)
}

/// What a run on central differences states, for a molecule with `n` coordinates.
pub fn note(n: usize) -> String {
    format!("note: {}", crate::runtime::finite_differences::note(n))
}
