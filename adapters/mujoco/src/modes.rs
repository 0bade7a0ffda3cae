//! Render modes, named once for both adapters and the renderer.

/// The only render mode (both adapters draw it).
pub(crate) const RGB_ARRAY: &str = "rgb_array";
