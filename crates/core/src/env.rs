//! The `Env` trait: Gymnasium's `reset`/`step` contract, writing into caller-owned buffers.

use crate::{EnvError, Space};
use std::borrow::Cow;
use std::collections::BTreeMap;

/// Options passed to `reset` (Gymnasium's `options=`), e.g. `{"qpos": [...]}`.
pub type ResetOptions = BTreeMap<String, serde_json::Value>;

/// One value of an info dict.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum InfoValue {
    /// A flag.
    Bool(bool),
    /// An integer.
    Int(i64),
    /// A number.
    Float(f64),
    /// A list of numbers (a small vector such as a goal).
    Floats(Vec<f64>),
    /// Text.
    Text(String),
}

/// The info dict of a `reset` or `step`. Reused across steps: `clear` keeps its capacity, so
/// an env that reports a few numbers per step does not allocate.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Info {
    items: Vec<(Cow<'static, str>, InfoValue)>,
}

impl Info {
    /// Removes every entry, keeping the allocation.
    pub fn clear(&mut self) {
        self.items.clear();
    }

    /// Sets `key` to `value`, replacing an earlier value of the same key.
    pub fn insert(&mut self, key: impl Into<Cow<'static, str>>, value: InfoValue) {
        let key = key.into();
        match self.items.iter_mut().find(|(k, _)| *k == key) {
            Some(slot) => slot.1 = value,
            None => self.items.push((key, value)),
        }
    }

    /// Sets a number.
    pub fn set_f64(&mut self, key: &'static str, value: f64) {
        self.insert(key, InfoValue::Float(value));
    }

    /// The value of `key`.
    pub fn get(&self, key: &str) -> Option<&InfoValue> {
        self.items.iter().find(|(k, _)| k == key).map(|(_, v)| v)
    }

    /// Entries in insertion order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &InfoValue)> {
        self.items.iter().map(|(k, v)| (k.as_ref(), v))
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// Whether there are no entries.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }
}

/// What a `step` returns besides the observation it wrote.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Transition {
    /// The reward of this step.
    pub reward: f64,
    /// The episode reached a terminal state of the MDP.
    pub terminated: bool,
    /// The episode was cut short (time limit or similar).
    pub truncated: bool,
}

/// One environment instance, with Gymnasium's semantics.
///
/// Observations are written into `obs`, a buffer of exactly
/// `observation_space().byte_len()` bytes laid out as the space describes. Actions arrive the
/// same way; the caller has already checked them against `action_space()`, so an env may
/// assume a valid action.
///
/// Seeding follows Gymnasium: `reset(Some(seed))` reseeds the env's generator, `reset(None)`
/// continues it, and the first reset without a seed draws one from the OS.
pub trait Env: Send {
    /// The space observations belong to.
    fn observation_space(&self) -> &Space;

    /// The space actions must belong to.
    fn action_space(&self) -> &Space;

    /// Starts a new episode and writes its first observation.
    fn reset(
        &mut self,
        seed: Option<u64>,
        options: &ResetOptions,
        obs: &mut [u8],
        info: &mut Info,
    ) -> Result<(), EnvError>;

    /// Advances one step with a valid `action` and writes the next observation.
    fn step(
        &mut self,
        action: &[u8],
        obs: &mut [u8],
        info: &mut Info,
    ) -> Result<Transition, EnvError>;

    /// Renders a frame (`render_mode = "rgb_array"`): `(height, width, rgb bytes)`.
    fn render(&mut self) -> Result<Option<(usize, usize, Vec<u8>)>, EnvError> {
        Ok(None)
    }

    /// Frames per second a recording of the rendered frames plays at: Gymnasium's
    /// `metadata["render_fps"]` (video writers such as `RecordVideo` read it). `None` when the
    /// env does not say.
    fn render_fps(&self) -> Option<f64> {
        None
    }

    /// Releases what the env holds. Called once; the env is not used afterwards.
    fn close(&mut self) {}
}
