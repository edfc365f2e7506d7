//! Variant tables: a table whose keys depend on one of them, its tag (`[integrator]
//! method = "rk4"`), each variant's keys a serde struct read with the place of every key and
//! value.
//!
//! serde's internally tagged enums (`#[serde(tag = "...")]`) buffer the table before dispatching,
//! which loses the places (`toml::Spanned` fields no longer deserialize, and an unknown key is
//! reported at the table's header). So the table is kept as written ([`RawVariantTable`], every
//! key and value with its place), [`VariantTable::read`] reads the tag, the caller selects the
//! variant by it, and [`VariantTable::keys`] deserializes the rest of the table into that
//! variant's struct (`#[derive(Deserialize)]`, `#[serde(deny_unknown_fields)]`, one
//! `Option<Spanned<T>>` field per key) with `spanned::deserialize`, each value at its place.
//! Before that it checks every key against the variant's fields ([`fields`]): a key of another
//! variant is refused at the key, naming the variants that take it; any other unknown key at the
//! key with a did-you-mean and the variant's keys.

use std::ops::Range;

use serde::Deserializer;
use serde::de::{self, DeserializeOwned, Visitor};
use toml::Spanned;

use super::spanned::{self, Value};
use super::{did_you_mean, spanned_error};
use crate::runtime::diagnostic::{FileError, Source};

/// A table as written: every key and value with its place.
pub type RawVariantTable = super::raw::RawTable<Value>;

/// The help of a message about a value of the wrong type (as for any other TOML error).
const TYPE_HELP: &str = "see the TOML syntax at https://toml.io and the shipped scenes/ for examples";

/// One variant as [`VariantTable::keys`] checks a table against it: its tag value and its keys.
#[derive(Clone, Copy, Debug)]
pub struct Variant {
    /// Its tag value (`"rk4"`).
    pub name: &'static str,
    /// The keys it takes besides the tag ([`fields`] of its struct).
    pub keys: &'static [&'static str],
}

/// A variant table with its tag read.
pub struct VariantTable<'a> {
    src: &'a Source<'a>,
    table: &'a RawVariantTable,
    tag_key: &'static str,
    tag: Spanned<String>,
}

impl<'a> VariantTable<'a> {
    /// Reads the tag `tag_key` of `table`, a string. A missing tag is refused at the table's
    /// place with `help`, a tag that is not a string at its value.
    ///
    /// # Errors
    ///
    /// A missing tag or a tag that is not a string.
    pub fn read(
        src: &'a Source<'a>,
        table: &'a RawVariantTable,
        tag_key: &'static str,
        help: &str,
    ) -> Result<Self, FileError> {
        let Some((_, value)) = table.get_ref().iter().find(|(k, _)| k.get_ref() == tag_key) else {
            let e = <spanned::Error as de::Error>::missing_field(tag_key);
            return Err(src.error(table.span(), e.message, help));
        };
        let tag = spanned::deserialize::<Spanned<String>>(value).map_err(|e| spanned_error(src, &e, TYPE_HELP))?;
        Ok(Self { src, table, tag_key, tag })
    }

    /// The tag's value.
    pub fn name(&self) -> &str {
        self.tag.get_ref()
    }

    /// Where the tag's value is written.
    pub fn name_span(&self) -> Range<usize> {
        self.tag.span()
    }

    /// Where the table is written.
    pub fn span(&self) -> Range<usize> {
        self.table.span()
    }

    /// An unknown tag, `unknown {what} `name``, at its place, with a did-you-mean among `names`
    /// before `help`.
    pub fn unknown(&self, what: &str, names: &[&str], help: &str) -> FileError {
        let help = match did_you_mean(self.name(), names.iter().copied()) {
            Some(m) => format!("did you mean \"{m}\"? {help}"),
            None => help.to_owned(),
        };
        self.src.error(self.tag.span(), format!("unknown {what} `{}`", self.name()), help)
    }

    /// The table but its tag, read into the keys `K` of the variant the tag names, every value
    /// with its place. First every key, in the order written, is checked against `K`'s fields:
    /// a key that another of `every` takes is refused at the key with `not_applicable(key)`
    /// naming the variants that take it, any other key that is not `K`'s with serde's
    /// "unknown field" (listing the tag and `K`'s keys), a did-you-mean and `keys_help`.
    ///
    /// # Errors
    ///
    /// A key `K` does not take, or a value of the wrong type (at the value, serde's message).
    pub fn keys<K: DeserializeOwned>(
        &self,
        every: &[Variant],
        not_applicable: impl Fn(&str) -> String,
        keys_help: &str,
    ) -> Result<K, FileError> {
        let takes = fields::<K>();
        let mut rest: Vec<(Spanned<String>, Spanned<Value>)> = Vec::new();
        for (key, value) in self.table.get_ref() {
            let name = key.get_ref().as_str();
            if name != self.tag_key {
                rest.push((key.clone(), value.clone()));
            }
        }
        // In the order written, so that the first key refused is the first in the file.
        rest.sort_by_key(|(k, _)| k.span().start);
        for (key, _) in &rest {
            let name = key.get_ref().as_str();
            if takes.contains(&name) {
                continue;
            }
            let takers: Vec<&str> = every.iter().filter(|v| v.keys.contains(&name)).map(|v| v.name).collect();
            if takers.is_empty() {
                return Err(self.unknown_key(key, takes, every, keys_help));
            }
            let help = match takers.as_slice() {
                [one] => format!("only the {one} method takes `{name}`: remove it, or choose that method"),
                many => format!("the {} methods take `{name}`: remove it, or choose one of them", and_list(many)),
            };
            return Err(self.src.error(key.span(), not_applicable(name), help));
        }
        let rest = Spanned::new(self.table.span(), Value::Table(rest));
        spanned::deserialize::<K>(&rest).map_err(|e| spanned_error(self.src, &e, TYPE_HELP))
    }

    /// A key no variant takes, at its place: serde's "unknown field" message listing the tag and
    /// `takes`, a did-you-mean among `takes` (or, failing that, among the other variants' keys,
    /// naming the variant), then `help`.
    fn unknown_key(&self, key: &Spanned<String>, takes: &[&str], every: &[Variant], help: &str) -> FileError {
        let word = key.get_ref().as_str();
        let mut expected = vec![self.tag_key];
        expected.extend_from_slice(takes);
        let message = format!("unknown field `{word}`, expected {}", one_of(&expected));
        let other = || {
            let all = every.iter().flat_map(|v| v.keys.iter().copied());
            let m = did_you_mean(word, all)?;
            let taker = every.iter().find(|v| v.keys.contains(&m))?;
            Some(format!("did you mean `{m}` (a key of the {} method)? ", taker.name))
        };
        let hint = match did_you_mean(word, expected.iter().copied()) {
            Some(m) => format!("did you mean `{m}`? "),
            None => other().unwrap_or_default(),
        };
        self.src.error(key.span(), message, format!("{hint}{help}"))
    }
}

/// `a`, `a and b`, `a, b and c`.
pub fn and_list(items: &[&str]) -> String {
    match items {
        [] => String::new(),
        [one] => (*one).to_owned(),
        [init @ .., last] => format!("{} and {last}", init.join(", ")),
    }
}

/// serde's list of expected fields: `` `a` ``, `` `a` or `b` ``, `` one of `a`, `b`, `c` ``.
fn one_of(names: &[&str]) -> String {
    let quoted: Vec<String> = names.iter().map(|n| format!("`{n}`")).collect();
    match quoted.as_slice() {
        [] => "no fields".to_owned(),
        [one] => one.clone(),
        [a, b] => format!("{a} or {b}"),
        many => format!("one of {}", many.join(", ")),
    }
}

/// The field names of a struct `T` deserializes (its keys), in their order, read from the
/// deserializer call its derived `Deserialize` makes.
///
/// # Panics
///
/// If `T` does not deserialize as a struct with named fields (a bug of the caller).
pub fn fields<T: DeserializeOwned>() -> &'static [&'static str] {
    struct Fields;

    #[derive(Debug)]
    struct Found(Option<&'static [&'static str]>);

    impl std::fmt::Display for Found {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("not a struct")
        }
    }

    impl std::error::Error for Found {}

    impl de::Error for Found {
        fn custom<D: std::fmt::Display>(_: D) -> Self {
            Found(None)
        }
    }

    impl<'de> Deserializer<'de> for Fields {
        type Error = Found;

        fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, Found> {
            Err(Found(None))
        }

        fn deserialize_struct<V: Visitor<'de>>(
            self,
            _: &'static str,
            fields: &'static [&'static str],
            _: V,
        ) -> Result<V::Value, Found> {
            Err(Found(Some(fields)))
        }

        serde::forward_to_deserialize_any! {
            bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf option unit
            unit_struct newtype_struct seq tuple tuple_struct map enum identifier ignored_any
        }
    }

    match T::deserialize(Fields) {
        Err(Found(Some(fields))) => fields,
        _ => panic!("{}: a variant's keys are a struct with named fields", std::any::type_name::<T>()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Keys {
        step: Option<Spanned<f64>>,
        stages: Option<Spanned<u32>>,
    }

    #[test]
    fn fields_are_the_struct_s_in_order() {
        assert_eq!(fields::<Keys>(), ["step", "stages"]);
    }

    #[test]
    fn lists_read_as_serde_and_prose_write_them() {
        assert_eq!(one_of(&["a"]), "`a`");
        assert_eq!(one_of(&["a", "b"]), "`a` or `b`");
        assert_eq!(one_of(&["a", "b", "c"]), "one of `a`, `b`, `c`");
        // serde's own wording, which the rest of a scene's messages use.
        let e = <spanned::Error as de::Error>::unknown_field("x", &["a", "b", "c"]);
        assert_eq!(e.message, "unknown field `x`, expected one of `a`, `b`, `c`");
        assert_eq!(and_list(&["a", "b", "c"]), "a, b and c");
        assert_eq!(and_list(&["a"]), "a");
    }
}
