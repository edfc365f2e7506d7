//! A table of the scene kept with a place at every depth, for a reader that deserializes it into
//! its own typed struct after the scene's one parse (the parse's tree borrows the text; this one
//! owns its values). [`Value`] is filled by toml's deserializer from that tree, every value and
//! key with its place; [`deserialize`] reads a [`Value`] into any serde type, giving
//! `toml::Spanned` fields their places and every error the place of the key or value it is
//! about, with serde's messages, as toml's own deserializer does.

use std::fmt;
use std::ops::Range;

use serde::de::value::StringDeserializer;
use serde::de::{self, DeserializeOwned, DeserializeSeed, IntoDeserializer, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Deserializer};
use serde_spanned::de::SpannedDeserializer;
use toml::Spanned;

/// A TOML value as written, every value and key with its place (dates and times are not kept:
/// no reader of a scene takes one, and one is refused as a type error when read).
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A string.
    String(String),
    /// An integer.
    Integer(i64),
    /// A float.
    Float(f64),
    /// A boolean.
    Boolean(bool),
    /// An array.
    Array(Vec<Spanned<Value>>),
    /// A table, its keys in the order written.
    Table(Vec<(Spanned<String>, Spanned<Value>)>),
}

impl Value {
    /// The entries of a table (none for another value).
    pub fn entries(&self) -> &[(Spanned<String>, Spanned<Value>)] {
        match self {
            Value::Table(t) => t,
            _ => &[],
        }
    }
}

/// Reads `value` into a `T`: every `Spanned` field with its place, an error at the place of what
/// it is about (a value of the wrong type at the value, an unknown key at the key, a missing key
/// at the table).
///
/// # Errors
///
/// Serde's error, with its place.
pub fn deserialize<T: DeserializeOwned>(value: &Spanned<Value>) -> Result<T, Error> {
    T::deserialize(ValueDeserializer { value: value.get_ref().clone(), span: value.span() })
}

/// Why a [`Value`] could not be read, and where.
#[derive(Clone, Debug, PartialEq)]
pub struct Error {
    /// Serde's message.
    pub message: String,
    /// The place of the key or value it is about.
    pub span: Option<Range<usize>>,
}

impl Error {
    fn at(mut self, span: &Range<usize>) -> Self {
        self.span.get_or_insert_with(|| span.clone());
        self
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Error {}

impl de::Error for Error {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        Error { message: msg.to_string(), span: None }
    }
}

// ---------------------------------------------------------------------------------------------
// Filled by toml's deserializer

impl<'de> Deserialize<'de> for Value {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_any(ValueVisitor)
    }
}

struct ValueVisitor;

impl<'de> Visitor<'de> for ValueVisitor {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a number, string, boolean, array or table")
    }

    fn visit_bool<E>(self, v: bool) -> Result<Value, E> {
        Ok(Value::Boolean(v))
    }

    fn visit_i64<E>(self, v: i64) -> Result<Value, E> {
        Ok(Value::Integer(v))
    }

    fn visit_u64<E: de::Error>(self, v: u64) -> Result<Value, E> {
        i64::try_from(v).map(Value::Integer).map_err(|_| E::custom(format!("integer {v} is out of range")))
    }

    fn visit_f64<E>(self, v: f64) -> Result<Value, E> {
        Ok(Value::Float(v))
    }

    fn visit_str<E>(self, v: &str) -> Result<Value, E> {
        Ok(Value::String(v.to_owned()))
    }

    fn visit_string<E>(self, v: String) -> Result<Value, E> {
        Ok(Value::String(v))
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut items = Vec::new();
        while let Some(item) = seq.next_element::<Spanned<Value>>()? {
            items.push(item);
        }
        Ok(Value::Array(items))
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let mut entries = Vec::new();
        // toml gives a date or time as a map whose one key has no place: the only key that is
        // not a `Spanned<String>`.
        let datetime = |_: A::Error| <A::Error as de::Error>::invalid_type(de::Unexpected::Other("datetime"), &self);
        while let Some(key) = map.next_key::<Spanned<String>>().map_err(datetime)? {
            entries.push((key, map.next_value::<Spanned<Value>>()?));
        }
        entries.sort_by_key(|(k, _)| k.span().start);
        Ok(Value::Table(entries))
    }
}

// ---------------------------------------------------------------------------------------------
// Read into a typed struct

/// One value with its place.
struct ValueDeserializer {
    value: Value,
    span: Range<usize>,
}

impl<'de> IntoDeserializer<'de, Error> for ValueDeserializer {
    type Deserializer = Self;

    fn into_deserializer(self) -> Self {
        self
    }
}

impl<'de> Deserializer<'de> for ValueDeserializer {
    type Error = Error;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Error> {
        let span = self.span;
        match self.value {
            Value::String(s) => visitor.visit_string(s),
            Value::Integer(i) => visitor.visit_i64(i),
            Value::Float(x) => visitor.visit_f64(x),
            Value::Boolean(b) => visitor.visit_bool(b),
            Value::Array(items) => {
                let mut seq = Items { items: items.into_iter() };
                let value = visitor.visit_seq(&mut seq)?;
                match seq.items.len() {
                    0 => Ok(value),
                    left => Err(de::Error::invalid_length(left, &"fewer elements in the array")),
                }
            }
            Value::Table(entries) => visitor.visit_map(Entries { entries: entries.into_iter(), value: None }),
        }
        .map_err(|e: Error| e.at(&span))
    }

    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Error> {
        visitor.visit_some(self)
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(self, _name: &'static str, visitor: V) -> Result<V::Value, Error> {
        visitor.visit_newtype_struct(self)
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, Error> {
        if serde_spanned::de::is_spanned(name) {
            let span = self.span.clone();
            return visitor.visit_map(SpannedDeserializer::new(self, span.clone())).map_err(|e: Error| e.at(&span));
        }
        let _ = fields;
        self.deserialize_any(visitor)
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _variants: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, Error> {
        let span = self.span.clone();
        match self.value {
            Value::String(s) => visitor.visit_enum(IntoDeserializer::<Error>::into_deserializer(s)),
            _ => self.deserialize_any(visitor),
        }
        .map_err(|e: Error| e.at(&span))
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf unit unit_struct
        seq tuple tuple_struct map identifier ignored_any
    }
}

struct Items {
    items: std::vec::IntoIter<Spanned<Value>>,
}

impl<'de> SeqAccess<'de> for Items {
    type Error = Error;

    fn next_element_seed<T: DeserializeSeed<'de>>(&mut self, seed: T) -> Result<Option<T::Value>, Error> {
        match self.items.next() {
            Some(item) => {
                let span = item.span();
                seed.deserialize(ValueDeserializer { value: item.into_inner(), span }).map(Some)
            }
            None => Ok(None),
        }
    }

    fn size_hint(&self) -> Option<usize> {
        Some(self.items.len())
    }
}

struct Entries {
    entries: std::vec::IntoIter<(Spanned<String>, Spanned<Value>)>,
    value: Option<Spanned<Value>>,
}

impl<'de> MapAccess<'de> for Entries {
    type Error = Error;

    fn next_key_seed<K: DeserializeSeed<'de>>(&mut self, seed: K) -> Result<Option<K::Value>, Error> {
        let Some((key, value)) = self.entries.next() else { return Ok(None) };
        self.value = Some(value);
        let span = key.span();
        seed.deserialize(KeyDeserializer { key: key.into_inner(), span: span.clone() })
            .map(Some)
            .map_err(|e| e.at(&span))
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, Error> {
        let value = self.value.take().ok_or_else(|| de::Error::custom("a value asked for before its key"))?;
        let span = value.span();
        seed.deserialize(ValueDeserializer { value: value.into_inner(), span })
    }

    fn size_hint(&self) -> Option<usize> {
        Some(self.entries.len())
    }
}

/// A key with its place.
struct KeyDeserializer {
    key: String,
    span: Range<usize>,
}

impl<'de> Deserializer<'de> for KeyDeserializer {
    type Error = Error;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Error> {
        visitor.visit_string(self.key)
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        _fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, Error> {
        if serde_spanned::de::is_spanned(name) {
            let key: StringDeserializer<Error> = self.key.into_deserializer();
            return visitor.visit_map(SpannedDeserializer::new(key, self.span));
        }
        self.deserialize_any(visitor)
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf option unit
        unit_struct newtype_struct seq tuple tuple_struct map enum identifier ignored_any
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Inner {
        x: Spanned<Vec<f64>>,
        name: Option<Spanned<String>>,
    }

    #[derive(Debug, Deserialize)]
    struct Outer {
        a: Spanned<f64>,
        inner: Option<Spanned<Inner>>,
        #[serde(default)]
        list: Vec<Spanned<u32>>,
    }

    fn table(text: &str) -> Spanned<Value> {
        #[derive(Deserialize)]
        struct Doc {
            t: Spanned<Value>,
        }
        let doc = toml::de::DeTable::parse(text).unwrap();
        Doc::deserialize(toml::de::Deserializer::from(doc)).unwrap().t
    }

    #[test]
    fn places_at_every_depth_as_toml_gives_them() {
        let text = "[t]\na = 3\nlist = [1, 2]\n[t.inner]\nx = [1.0, 2.5]\nname = \"n\"\n";
        let outer: Outer = deserialize(&table(text)).unwrap();
        let direct: Outer = {
            #[derive(Deserialize)]
            struct Doc {
                t: Outer,
            }
            Doc::deserialize(toml::de::Deserializer::from(toml::de::DeTable::parse(text).unwrap())).unwrap().t
        };
        assert_eq!(*outer.a.get_ref(), 3.0);
        assert_eq!(outer.a.span(), direct.a.span());
        let (i, j) = (outer.inner.unwrap(), direct.inner.unwrap());
        assert_eq!(i.span(), j.span());
        assert_eq!(i.get_ref().x.span(), j.get_ref().x.span());
        assert_eq!(i.get_ref().name.as_ref().unwrap().span(), j.get_ref().name.as_ref().unwrap().span());
        assert_eq!(outer.list.iter().map(|x| x.span()).collect::<Vec<_>>(), vec![18..19, 21..22]);
    }

    #[test]
    fn errors_at_the_key_or_value_they_are_about() {
        let text = "[t]\na = 3\n[t.inner]\nx = [1.0, \"s\"]\n";
        let e = deserialize::<Outer>(&table(text)).unwrap_err();
        assert_eq!(e.message, "invalid type: string \"s\", expected f64");
        assert_eq!(&text[e.span.unwrap()], "\"s\"");
        let text = "[t]\na = 3\ninner = { x = [1.0], nam = \"n\" }\n";
        let e = deserialize::<Outer>(&table(text)).unwrap_err();
        assert_eq!(e.message, "unknown field `nam`, expected `x` or `name`");
        assert_eq!(&text[e.span.unwrap()], "nam");
        let text = "[t]\na = \"3\"\n";
        let e = deserialize::<Outer>(&table(text)).unwrap_err();
        assert_eq!(&text[e.span.unwrap()], "\"3\"");
        let text = "[t]\nlist = [1]\n";
        let e = deserialize::<Outer>(&table(text)).unwrap_err();
        assert_eq!(e.message, "missing field `a`");
        let text = "[t]\na = 1\nlist = [-1]\n";
        let e = deserialize::<Outer>(&table(text)).unwrap_err();
        assert_eq!(&text[e.span.unwrap()], "-1");
        // A date is no value of a scene: refused by toml's deserializer, at its place.
        #[derive(Debug, Deserialize)]
        #[allow(dead_code)]
        struct Doc {
            t: Spanned<Value>,
        }
        let text = "[t]\na = 1979-05-27\n";
        let e = Doc::deserialize(toml::de::Deserializer::from(toml::de::DeTable::parse(text).unwrap())).unwrap_err();
        assert_eq!(e.message(), "invalid type: datetime, expected a number, string, boolean, array or table");
        assert_eq!(&text[e.span().unwrap()], "1979-05-27");
    }
}
