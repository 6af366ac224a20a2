//! Values by name in a fixed order (parameters in the campaign's order, outputs in the
//! order compared), written as a JSON object in that order.

use serde::de::{MapAccess, Visitor};
use serde::ser::SerializeMap;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;
use std::marker::PhantomData;

/// Values by name, in order; a name appears once.
#[derive(Debug, Clone, PartialEq)]
pub struct Named<T>(Vec<(String, T)>);

impl<T> Default for Named<T> {
    fn default() -> Self {
        Self(Vec::new())
    }
}

impl<T> Named<T> {
    /// The value of `name`, if it has one.
    pub fn get(&self, name: &str) -> Option<&T> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, v)| v)
    }

    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.0.iter().map(|(n, _)| n.as_str())
    }

    pub fn iter(&self) -> impl Iterator<Item = (&str, &T)> {
        self.0.iter().map(|(n, v)| (n.as_str(), v))
    }

    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Set `name` to `value`: a name already present keeps its place and takes the new
    /// value (as a JSON object built key by key does).
    pub fn insert(&mut self, name: String, value: T) {
        match self.0.iter_mut().find(|(n, _)| *n == name) {
            Some(entry) => entry.1 = value,
            None => self.0.push((name, value)),
        }
    }
}

impl<T> FromIterator<(String, T)> for Named<T> {
    fn from_iter<I: IntoIterator<Item = (String, T)>>(entries: I) -> Self {
        let mut named = Self::default();
        for (n, v) in entries {
            named.insert(n, v);
        }
        named
    }
}

impl<T: Serialize> Serialize for Named<T> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (n, v) in &self.0 {
            map.serialize_entry(n, v)?;
        }
        map.end()
    }
}

/// A value of a [`Named`] as `result.json` holds it: a number that is not finite is
/// written `null` (JSON has no infinity) and reads back as `+∞`.
pub trait Entry: Sized {
    fn from_null() -> Option<Self>;
}

impl Entry for f64 {
    fn from_null() -> Option<Self> {
        Some(f64::INFINITY)
    }
}

impl<T> Entry for Option<T> {
    fn from_null() -> Option<Self> {
        Some(None)
    }
}

impl Entry for (f64, f64) {
    fn from_null() -> Option<Self> {
        None
    }
}

impl Entry for super::Range {
    fn from_null() -> Option<Self> {
        None
    }
}

impl<'de, T: Deserialize<'de> + Entry> Deserialize<'de> for Named<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Entries<T>(PhantomData<T>);
        impl<'de, T: Deserialize<'de> + Entry> Visitor<'de> for Entries<T> {
            type Value = Named<T>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("an object of values by name")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Named<T>, A::Error> {
                let mut named = Named::default();
                while let Some((name, value)) = map.next_entry::<String, Option<T>>()? {
                    let value = match value.or_else(T::from_null) {
                        Some(v) => v,
                        None => return Err(serde::de::Error::custom(format!("`{name}` is null"))),
                    };
                    named.insert(name, value);
                }
                Ok(named)
            }
        }
        d.deserialize_map(Entries(PhantomData))
    }
}
