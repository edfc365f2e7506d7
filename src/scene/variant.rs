//! Variant tables: a table whose keys depend on one of them (a tag such as `[integrator]
//! method = "rk4"`), read with the place of every key and value.
//!
//! serde's tagged and untagged enums buffer the table before dispatching, which loses the
//! places (`toml::Spanned` fields no longer deserialize, and an unknown key is reported at the
//! table's header). Here the table is read as a map of spanned keys to spanned values
//! ([`RawVariantTable`], which toml's own deserializer fills with every place), [`Tagged`]
//! reads the tag, and each variant names the keys it takes ([`Tagged::only`]) and reads each
//! value into its type ([`Tagged::get`]); every error points at the key or value it is about.

use std::ops::Range;

use serde::de::{DeserializeOwned, Error as _};
use toml::Spanned;

use super::toml_message;
use crate::runtime::diagnostic::{FileError, Source};

/// A table as written: every key and value with its place.
pub type RawVariantTable = super::raw::RawTable<toml::Value>;

/// The help of a message about a value of the wrong type (as for any other TOML error).
const TYPE_HELP: &str = "see the TOML syntax at https://toml.io and the shipped scenes/ for examples";

/// A variant table with its tag read.
pub struct Tagged<'a> {
    src: &'a Source<'a>,
    table: &'a RawVariantTable,
    tag: Spanned<String>,
}

impl<'a> Tagged<'a> {
    /// Reads `table`, whose keys are `keys` (every variant's, tag first, in the order in which
    /// errors about them are reported) and whose tag is `keys[0]`, a string. A key not in `keys`
    /// is refused at its place as serde refuses an unknown field, with `help`; a missing tag at
    /// the table's place.
    ///
    /// # Errors
    ///
    /// An unknown key, a missing tag or a tag that is not a string.
    pub fn read(
        src: &'a Source<'a>,
        table: &'a RawVariantTable,
        keys: &'static [&'static str],
        help: &str,
    ) -> Result<Self, FileError> {
        let error = |span: Range<usize>, e: toml::de::Error, help: &str| src.error(span, toml_message(&e), help);
        // Keys in the order written, so that the first unknown one is the one reported.
        let mut written: Vec<&Spanned<String>> = table.get_ref().keys().collect();
        written.sort_by_key(|k| k.span().start);
        if let Some(k) = written.into_iter().find(|k| !keys.contains(&k.get_ref().as_str())) {
            return Err(error(k.span(), toml::de::Error::unknown_field(k.get_ref(), keys), help));
        }
        let tag_key = keys[0];
        let Some((_, value)) = table.get_ref().iter().find(|(k, _)| k.get_ref() == tag_key) else {
            return Err(error(table.span(), toml::de::Error::missing_field(tag_key), help));
        };
        let tag = typed::<String>(value).map_err(|e| error(value.span(), e, TYPE_HELP))?;
        Ok(Self { src, table, tag })
    }

    /// The tag's value.
    pub fn name(&self) -> &str {
        self.tag.get_ref()
    }

    /// Where the tag's value is written.
    pub fn name_span(&self) -> Range<usize> {
        self.tag.span()
    }

    /// Refuses the first key (in the order of `all`, the table's keys) that is neither the tag
    /// nor one of `keys`: at the key's place, with the message `refuse(key)` and `help`.
    ///
    /// # Errors
    ///
    /// The first such key.
    pub fn only(
        &self,
        all: &[&str],
        keys: &[&str],
        refuse: impl Fn(&str) -> String,
        help: &str,
    ) -> Result<(), FileError> {
        for key in all.iter().skip(1).filter(|k| !keys.contains(k)) {
            if let Some(span) = self.key_span(key) {
                return Err(self.src.error(span, refuse(key), help));
            }
        }
        Ok(())
    }

    /// Where `key` is written, if it is.
    pub fn key_span(&self, key: &str) -> Option<Range<usize>> {
        self.table.get_ref().keys().find(|k| k.get_ref() == key).map(|k| k.span())
    }

    /// The value of `key` as a `T`, with its place.
    ///
    /// # Errors
    ///
    /// A value that is not a `T`, at the value's place with serde's message.
    pub fn get<T: DeserializeOwned>(&self, key: &str) -> Result<Option<Spanned<T>>, FileError> {
        let Some((_, value)) = self.table.get_ref().iter().find(|(k, _)| k.get_ref() == key) else {
            return Ok(None);
        };
        typed(value).map(Some).map_err(|e| self.src.error(value.span(), toml_message(&e), TYPE_HELP))
    }

    /// An unknown tag, `unknown {what} `name``, at its place, with a did-you-mean among `names`
    /// before `help`.
    pub fn unknown(&self, what: &str, names: &[&str], help: &str) -> FileError {
        let help = match super::did_you_mean(self.name(), names.iter().copied()) {
            Some(m) => format!("did you mean \"{m}\"? {help}"),
            None => help.to_owned(),
        };
        self.src.error(self.tag.span(), format!("unknown {what} `{}`", self.name()), help)
    }

    /// Where the table is written.
    pub fn span(&self) -> Range<usize> {
        self.table.span()
    }
}

/// A value read into its type, keeping its place.
fn typed<T: DeserializeOwned>(value: &Spanned<toml::Value>) -> Result<Spanned<T>, toml::de::Error> {
    T::deserialize(value.get_ref().clone()).map(|v| Spanned::new(value.span(), v))
}
