//! Serde helpers for errors that cross a process boundary (a daemon's, a remote hub's): names
//! held as `&'static str` and I/O errors, which serde cannot rebuild on its own.

use serde::{Deserialize, Deserializer, Serializer};

/// `&'static str`, named so that serde does not take a field of this type as borrowed from
/// the input (it reads one through [`interned`]).
pub type StaticName = &'static str;

/// A name sent by the daemon where the error holds a `&'static str` (an option's or a
/// field's name: a handful of distinct values), leaked once per distinct value and capped, so
/// a misbehaving daemon cannot grow the client without bound.
pub fn interned<'de, D: Deserializer<'de>>(d: D) -> Result<&'static str, D::Error> {
    const CAPACITY: usize = 64;
    static SEEN: std::sync::Mutex<Vec<&'static str>> = std::sync::Mutex::new(Vec::new());
    let name = String::deserialize(d)?;
    let mut seen = SEEN.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(known) = seen.iter().find(|known| **known == name) {
        return Ok(known);
    }
    if seen.len() == CAPACITY {
        return Ok("value");
    }
    let leaked: &'static str = Box::leak(name.into_boxed_str());
    seen.push(leaked);
    Ok(leaked)
}

/// An I/O error as its text (rebuilt as an `io::Error` of kind `Other` with that text).
pub mod io_text {
    use super::*;

    /// Writes the error's text.
    pub fn serialize<S: Serializer>(e: &std::io::Error, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&e.to_string())
    }

    /// Reads the text back as an error of kind `Other`.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<std::io::Error, D::Error> {
        Ok(std::io::Error::other(String::deserialize(d)?))
    }
}
