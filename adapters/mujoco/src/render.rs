//! `render_mode="rgb_array"`: MuJoCo's own offscreen renderer on an EGL context.
//!
//! Without a GPU, Mesa's software EGL (`libegl1 libegl-mesa0 libgl1-mesa-dri`, which `make`
//! installs) draws the frames on the CPU. The context is created at the first `render`, so
//! envs that never render cost nothing, and a machine where EGL cannot work gets an error that
//! says why at that point.

use envhub_core::{EnvConfig, EnvError, ExtraKeys};
use mujoco_rs::prelude::*;
use mujoco_rs::renderer::MjRenderer;
use std::sync::Arc;

/// Gymnasium's `DEFAULT_SIZE`.
const DEFAULT_SIZE: u64 = 480;

/// The `extra` keys rendering takes (Gymnasium's `MujocoEnv` kwargs).
pub(crate) const OPTIONS: &[&str] = &["width", "height", "camera_id", "camera_name"];

/// The only render mode.
const RGB_ARRAY: &str = "rgb_array";

/// What to draw: image size and camera.
#[derive(Clone, Debug)]
pub(crate) struct RenderSetup {
    pub(crate) width: u32,
    pub(crate) height: u32,
    camera_id: Option<u64>,
    camera_name: Option<String>,
}

impl RenderSetup {
    /// Reads `render_mode` and the render options; `None` when the env does not render.
    pub(crate) fn from_config(
        env_id: &str,
        config: &EnvConfig,
        keys: &ExtraKeys,
    ) -> Result<Option<RenderSetup>, EnvError> {
        let width = keys.u64("width", DEFAULT_SIZE)?;
        let height = keys.u64("height", DEFAULT_SIZE)?;
        let camera_id = config
            .extra
            .get("camera_id")
            .map(|_| keys.u64("camera_id", 0));
        let camera_id = camera_id.transpose()?;
        let camera_name = keys.str("camera_name")?.map(str::to_string);
        if camera_id.is_some() && camera_name.is_some() {
            return Err(keys.error(
                "camera_name",
                "give `camera_id` or `camera_name`, not both (as Gymnasium requires)",
            ));
        }
        for (key, v) in [("width", width), ("height", height)] {
            if v == 0 || v > 16384 {
                return Err(keys.error(key, format!("must be 1 to 16384 pixels, got {v}")));
            }
        }
        match config.render_mode.as_deref() {
            None => Ok(None),
            Some(RGB_ARRAY) => Ok(Some(RenderSetup {
                width: width as u32,
                height: height as u32,
                camera_id,
                camera_name,
            })),
            Some(mode) => Err(EnvError::RenderMode {
                env_id: env_id.to_string(),
                mode: mode.to_string(),
                supported: vec![RGB_ARRAY.into()],
            }),
        }
    }

    /// The camera as MuJoCo takes it: a named or numbered fixed camera, else the free camera.
    fn camera(&self, env_id: &str, model: &MjModel) -> Result<MjvCamera, EnvError> {
        let ncam = model.ffi().ncam as usize;
        let id = match (&self.camera_name, self.camera_id) {
            (Some(name), _) => Some(
                model
                    .name_to_id(MjtObjBase::mjOBJ_CAMERA, name)
                    .ok_or_else(|| EnvError::InvalidOption {
                        env_id: env_id.to_string(),
                        key: "camera_name".into(),
                        reason: format!("the model has no camera `{name}`{}", cameras(model)),
                    })?,
            ),
            (None, Some(id)) if id as usize >= ncam => {
                return Err(EnvError::InvalidOption {
                    env_id: env_id.to_string(),
                    key: "camera_id".into(),
                    reason: format!("the model has {ncam} cameras{}", cameras(model)),
                });
            }
            (None, Some(id)) => Some(id as usize),
            (None, None) => None,
        };
        Ok(match id {
            Some(id) => MjvCamera::new_fixed(id),
            None => MjvCamera::new_free(model),
        })
    }
}

fn cameras(model: &MjModel) -> String {
    let names: Vec<String> = (0..model.ffi().ncam as usize)
        .map(|i| {
            let name = model.id_to_name(MjtObjBase::mjOBJ_CAMERA, i).unwrap_or("");
            format!("{i} `{name}`")
        })
        .collect();
    if names.is_empty() {
        String::new()
    } else {
        format!("; it has {}", names.join(", "))
    }
}

/// An offscreen renderer bound to one model.
pub(crate) struct Renderer {
    inner: MjRenderer,
    width: usize,
    height: usize,
}

// SAFETY: the renderer owns its EGL context and surface; `render` makes the context current on
// the calling thread before drawing, and an env (hence its renderer) is used by one thread at a
// time (`&mut self`), which is all EGL requires to move a context between threads.
unsafe impl Send for Renderer {}

impl Renderer {
    pub(crate) fn new(
        env_id: &str,
        setup: &RenderSetup,
        model: &MjModel,
    ) -> Result<Self, EnvError> {
        let camera = setup.camera(env_id, model)?;
        let inner = MjRenderer::builder()
            .width(setup.width)
            .height(setup.height)
            .camera(camera)
            .build(model)
            .map_err(|e| EnvError::Simulator {
                env_id: env_id.to_string(),
                reason: format!(
                    "cannot render offscreen: {}\nhint: rendering needs EGL; without a GPU, \
                     Mesa's software EGL: `apt-get install libegl1 libegl-mesa0 \
                     libgl1-mesa-dri` (`make setup` does it)",
                    chain(&e)
                ),
            })?;
        Ok(Renderer {
            inner,
            width: setup.width as usize,
            height: setup.height as usize,
        })
    }

    /// Draws the current state: `(height, width, rgb)`, row 0 at the top.
    pub(crate) fn render(
        &mut self,
        env_id: &str,
        data: &mut MjData<Arc<MjModel>>,
    ) -> Result<(usize, usize, Vec<u8>), EnvError> {
        let failed = |e: &dyn std::error::Error| EnvError::Simulator {
            env_id: env_id.to_string(),
            reason: format!("rendering failed: {}", chain(e)),
        };
        self.inner.sync_data(data).map_err(|e| failed(&e))?;
        self.inner.render().map_err(|e| failed(&e))?;
        let rgb = self.inner.rgb_flat().unwrap_or_default().to_vec();
        Ok((self.height, self.width, rgb))
    }
}

/// An error and its causes, `: `-separated.
fn chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        text.push_str(&format!(": {c}"));
        cause = c.source();
    }
    text
}
